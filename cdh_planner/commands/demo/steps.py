"""What the demo's stories share: a ``Step`` and the table printer."""

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class Step:
    """One step of the demo: ``run(demo)`` prints what it shows and records its verdicts."""

    name: str
    title: str
    run: Callable[[object], None]


def table(header, rows):
    """Print rows as left-aligned columns under a header."""
    widths = [max(len(str(r[j])) for r in [header] + rows) for j in range(len(header))]
    for r in [header] + rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip())
