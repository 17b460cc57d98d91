"""The README's and the manual's examples, run: a fenced ``console`` block after an HTML
comment ``<!-- example ... -->`` is executed and its output compared with what it shows.

Marker options (space-separated, after ``example``):
- ``slow``: the block plans for more than a few seconds (run under ``pytest -m slow``);
- ``measured="REGEX"``: spans of the output that are measurements (times, file names with
  a date) and may differ; ``measured`` alone means times (``0.297 s``, ``12 ms``).

In the block, a line ``$ COMMAND`` (continued by lines ending in ``\\``) is a command; the
lines up to the next command are its expected standard output, then ``[exit N]`` when it
exits with N != 0; a line ``...`` stands for any number of lines (a trimmed output). A command ending in ``&`` runs in the background (give it a redirect);
background jobs are stopped by SIGINT when the block ends. A block runs as one bash script
in a temporary folder holding a link to the repository's ``config/``, with the venv's
``bin`` first on PATH, a HOME and a ROS domain of its own (discovery on localhost).

    python test/doc_examples.py [--update] [FILE.md ...]

checks every marked block (``--update``: rewrites each block's output with what the
commands print now; review the diff).
"""

import os
import re
import shlex
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
MARKER = re.compile(r"^<!--\s*example\b(?P<opts>.*?)-->\s*$")
TIMES = r"\d+(?:\.\d+)?(?:e[-+]?\d+)? ?(?:s|ms|us)\b"
BLOCK_TIMEOUT_S = 300
SEP = "@@cdh-example-{}@@"  # printed before each command's output


@dataclass
class Example:
    """One marked block: where it is, its commands and their expected outputs."""
    path: Path
    line: int                  # 1-based line of the opening fence
    end: int                   # 1-based line of the closing fence
    commands: list = field(default_factory=list)   # (command text, expected lines)
    slow: bool = False
    measured: str = ""

    @property
    def name(self):
        path = self.path.relative_to(REPO) if REPO in self.path.parents else self.path
        return f"{path}:{self.line}"


def find_examples(paths=DOCS):
    """Every marked block of the given markdown files."""
    out = []
    for path in paths:
        lines = path.read_text().splitlines()
        i = 0
        while i < len(lines):
            m = MARKER.match(lines[i])
            if m and i + 1 < len(lines) and lines[i + 1].startswith("```"):
                ex, i = _read_block(path, lines, i + 1, m.group("opts"))
                out.append(ex)
            i += 1
    return out


def _read_block(path, lines, start, opts):
    """The Example whose fence opens at ``lines[start]``, and the index of its closing fence."""
    ex = Example(path, start + 1, start + 1)
    words = shlex.split(opts)
    ex.slow = "slow" in words
    for w in words:
        if w == "measured":
            ex.measured = TIMES
        elif w.startswith("measured="):
            ex.measured = w.split("=", 1)[1]
    j = start + 1
    while j < len(lines) and not lines[j].startswith("```"):
        line = lines[j]
        if line.startswith("$ "):
            cmd = line[2:]
            while cmd.endswith("\\") and j + 1 < len(lines):
                j += 1
                cmd += "\n" + lines[j]
            ex.commands.append((cmd, []))
        elif ex.commands:
            ex.commands[-1][1].append(line)
        j += 1
    ex.end = j + 1
    return ex, j


def run(ex):
    """The outputs (one list of lines per command) the example's commands print now."""
    with tempfile.TemporaryDirectory(prefix="cdh_example_") as tmp:
        tmp = Path(tmp)
        (tmp / "config").symlink_to(REPO / "config")
        (tmp / "home").mkdir()
        script = ["set -u", "trap 'kill -INT $(jobs -p) 2>/dev/null; wait' EXIT"]
        for k, (cmd, _) in enumerate(ex.commands):
            script.append(f"printf '%s\\n' {shlex.quote(SEP.format(k))}")
            if cmd.rstrip().endswith("&"):
                script.append(cmd)
            else:
                script.append(f"{cmd}\nrc=$?; [ $rc -ne 0 ] && echo \"[exit $rc]\"")
        env = _environment(tmp)
        sys.path.insert(0, str(REPO))
        from cdh_planner.ros.isolation import claimed_domain
        with claimed_domain() as domain:
            env["ROS_DOMAIN_ID"] = str(domain)
            done = subprocess.run(["bash", "-c", "\n".join(script)], cwd=tmp, env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                  timeout=BLOCK_TIMEOUT_S, stdin=subprocess.DEVNULL)
    outputs, current = [], None
    for line in done.stdout.splitlines():
        if re.fullmatch(SEP.format(r"\d+"), line):
            current = []
            outputs.append(current)
        elif current is not None:
            current.append(line.rstrip())
    return outputs


def _environment(tmp):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "PYTEST"))}
    env.update(PATH=f"{REPO / '.venv' / 'bin'}:{env.get('PATH', '/usr/bin:/bin')}",
               HOME=str(tmp / "home"), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               AMENT_PREFIX_PATH=str(REPO / ".venv"), COLUMNS="100", PYTHONHASHSEED="0")
    return env


def normalised(lines, measured):
    """Lines without trailing blanks, each measured span replaced by one mark."""
    out = [line.rstrip() for line in lines]
    while out and not out[-1]:
        out.pop()
    if measured:
        out = [re.sub(measured, "<measured>", line) for line in out]
    return out


def matches(want, got):
    """Do the lines ``got`` match ``want``, where a line ``...`` matches any lines?"""
    if not want:
        return not got
    if want[0] == "...":
        return any(matches(want[1:], got[k:]) for k in range(len(got) + 1))
    return bool(got) and want[0] == got[0] and matches(want[1:], got[1:])


def differences(ex, outputs):
    """What differs between the example's expected and actual outputs ("" if nothing)."""
    if len(outputs) != len(ex.commands):
        return f"{ex.name}: {len(outputs)} of {len(ex.commands)} commands ran"
    for (cmd, expected), actual in zip(ex.commands, outputs):
        want, got = normalised(expected, ex.measured), normalised(actual, ex.measured)
        if not matches(want, got):
            return (f"{ex.name}: `{cmd}` printed\n" + "\n".join(actual) +
                    "\n-- the docs show --\n" + "\n".join(expected))
    return ""


def update(ex, outputs):
    """Rewrite the example's block in its file with ``outputs`` (whole: trim it again by hand
    with ``...`` where the page shows only a part)."""
    lines = ex.path.read_text().splitlines()
    body = []
    for (cmd, _), out in zip(ex.commands, outputs):
        body.append("$ " + cmd)
        body.extend(normalised(out, ""))
    lines[ex.line:ex.end - 1] = body
    ex.path.write_text("\n".join(lines) + "\n")


def main(argv):
    do_update = "--update" in argv
    paths = [Path(a).resolve() for a in argv if not a.startswith("--")] or DOCS
    failed = 0
    for ex in reversed(find_examples(paths)):   # bottom up: an update keeps earlier line numbers
        outputs = run(ex)
        diff = differences(ex, outputs)
        if diff and do_update:
            update(ex, outputs)
            print(f"updated {ex.name}")
        elif diff:
            failed += 1
            print(diff, end="\n\n")
        else:
            print(f"ok {ex.name}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
