"""The atlas' growth as a progress bar on stderr (tqdm), for the command line.

    with chart_progress(quiet=False) as update:
        update(charts, best_h)          # each progress report: charts so far, heuristic
"""

from contextlib import contextmanager

from tqdm import tqdm


@contextmanager
def chart_progress(quiet=False):
    """A tqdm bar counting charts, with the search's best remaining distance estimate
    (task units); yields ``update(charts, best_h)``. Cleared when done."""
    with tqdm(total=None, unit="chart", desc="atlas", disable=quiet, leave=False) as bar:
        def update(charts, best_h):
            bar.n = int(charts)
            bar.set_postfix(best_h=f"{best_h:.3g}", refresh=False)
            bar.refresh()
        yield update
