"""Run the tutorial's commands and compare every figure its pages quote with what they print.

The tutorial pages (``docs/tutorial/*.md``, in the order of their toctree) are read as
a script: each ````` ```bash ````` block is run (in one scratch folder shared by all
pages, as the tutorial says), and the ````` ```text ````` block right after it is the
output the page quotes. A quoted line is found among the printed lines by its *shape*
(the line with every number replaced by ``#``); then each number on it is compared
with the printed one.

Tolerance (stated once, here): a quoted number must equal the printed one to the
precision quoted (``0.927`` matches 0.9274 but not 0.894; ``334`` matches 334 only),
unless the block carries ``% check: rtol: R`` (relative tolerance R, for the few
commands whose output depends on the machine's speed, e.g. ``fly`` with measured
latency). Timings are never compared: a number followed by ``s``, ``ms`` or ``min``,
and every number in a table column whose header names ``(s)``, ``(ms)`` or a latency.

Annotations are MyST comment lines (``% ...``: not rendered) right before a block:

``% check: skip: REASON``
    do not run this command / do not compare this output, and say why.
``% check: file: PATH``
    the next ``text`` block quotes the file PATH (written by the commands before it).
``% check: script: NAME``
    the next ``python`` block is saved as NAME and run with ``python NAME``; the
    ``text`` block after it is its output.
``% check: rtol: R``
    the next output block is compared with relative tolerance R.
``% check: status: N``
    the next command is expected to exit with status N (an error shown on purpose).
``% check: replace: OLD => NEW``
    run the next command with OLD replaced by NEW (e.g. the lean venv's path by the
    installed command), and say so on the page.

A shell variable set on its own line (``S=moving/dyn-0000-0000``) holds for the rest
of its page. Run from the command line (``python tests/tutorial_check.py [PAGE ...]``) it
runs the pages and prints each block's problems; ``tests/test_tutorial_figures.py`` runs
it under pytest.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TUTORIAL = ROOT / "docs" / "tutorial"
PAGES = ("install", "demo", "own-geotiff", "compare", "moving", "fly", "onboard", "dask")
"""The pages in the order of ``docs/tutorial/index.md``'s toctree."""

_FENCE = re.compile(r"^```(\w*)\s*$")
_NOTE = re.compile(r"^%\s*check:\s*([\w-]+)\s*:?\s*(.*)$")
_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![\w])")
_TIME_AFTER = re.compile(r"^\s*(s|ms|min)\b")
_TIMING_HEADER = re.compile(r"\((?:s|ms)\)|latency|runtime", re.IGNORECASE)
_ASSIGN = re.compile(r"^[A-Za-z_]\w*=\S+$")


@dataclass
class Block:
    """A fenced block of a page with the annotations before it."""

    lang: str
    text: str
    line: int
    notes: dict[str, str] = field(default_factory=dict)


@dataclass
class Step:
    """A command (or script) and the output the page quotes for it."""

    page: str
    line: int
    command: str | None  # shell text to run (None: only an output block, e.g. a file)
    quoted: str | None  # the quoted output (None: nothing quoted)
    notes: dict[str, str]
    skip: str | None = None  # reason, when not run/compared


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown page, each with the ``% check:`` notes before it."""
    out: list[Block] = []
    notes: dict[str, str] = {}
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = _NOTE.match(lines[i])
        if m:
            notes[m.group(1)] = m.group(2).strip()
            i += 1
            continue
        f = _FENCE.match(lines[i])
        if f and lines[i].startswith("```") and not lines[i].startswith("```{"):
            start = i
            body = []
            i += 1
            while i < len(lines) and not lines[i].startswith("```"):
                body.append(lines[i])
                i += 1
            out.append(Block(f.group(1), "\n".join(body), start + 1, notes))
            notes = {}
        elif lines[i].strip():
            notes = {} if not lines[i].startswith("%") else notes
        i += 1
    return out


def steps(page: str) -> list[Step]:
    """The page as steps: each command with the output quoted right after it."""
    bl = blocks(TUTORIAL / f"{page}.md")
    out: list[Step] = []
    i = 0
    while i < len(bl):
        b = bl[i]
        nxt = bl[i + 1] if i + 1 < len(bl) and bl[i + 1].lang == "text" else None
        if nxt is not None and "file" in nxt.notes:
            nxt = None  # quotes a file, not this command's output
        if b.lang in ("bash", "python"):
            command = b.text
            if b.lang == "python":
                name = b.notes.get("script")
                command = f"cat > {name} <<'PYEOF'\n{b.text}\nPYEOF\npython {name}" if name else ""
            skip = b.notes.get("skip") or (None if command else "a python block without a script")
            quoted = nxt.text if nxt is not None else None
            notes = {**b.notes, **(nxt.notes if nxt is not None else {})}
            if nxt is not None and nxt.notes.get("skip"):
                quoted = None
            out.append(Step(page, b.line, command, quoted, notes, skip))
            i += 2 if nxt is not None else 1
        elif b.lang == "text":
            skip = b.notes.get("skip")
            if "file" in b.notes:
                out.append(Step(page, b.line, None, b.text, b.notes))
            else:
                out.append(Step(page, b.line, None, b.text, b.notes, skip or "UNEXPLAINED"))
            i += 1
        else:
            i += 1
    return out


def numbers(line: str, timing_columns: set[int] | None = None) -> list[tuple[str, bool]]:
    """The numbers of a line as ``(text, is_timing)``, in order.

    A number followed by a time unit is a timing; in a Markdown table row, so is every
    number in a column listed in ``timing_columns``.
    """
    cells = line.split("|") if line.lstrip().startswith("|") else None
    out = []
    for m in _NUMBER.finditer(line):
        timing = bool(_TIME_AFTER.match(line[m.end() :]))
        if cells is not None and timing_columns:
            column = line[: m.start()].count("|") - 1
            timing = timing or column in timing_columns
        out.append((m.group(0), timing))
    return out


def shape(line: str) -> str:
    """The line with each number as ``#`` and runs of blanks as one (how lines are matched)."""
    return " ".join(_NUMBER.sub("#", line).split())


def _timing_columns(header: str) -> set[int]:
    cells = header.split("|")[1:-1]
    return {k for k, c in enumerate(cells) if _TIMING_HEADER.search(c)}


def agrees(quoted: str, printed: str, rtol: float | None) -> bool:
    """Whether a printed number agrees with a quoted one (see the module docstring)."""
    q, p = float(quoted), float(printed)
    if rtol is not None:
        return abs(p - q) <= rtol * max(abs(q), 1e-12) + 1e-12
    decimals = len(quoted.split(".")[1]) if "." in quoted and "e" not in quoted.lower() else 0
    return abs(p - q) <= 0.5 * 10.0**-decimals + 1e-9


def compare(quoted: str, printed: str, rtol: float | None = None) -> list[str]:
    """Problems between a quoted output and the printed one (empty: they agree).

    Parameters
    ----------
    quoted : the page's ``text`` block (lines ``...`` mark trimmed output).
    printed : what the command printed (stdout and stderr) or the file holds.
    rtol : relative tolerance; ``None``: equal to the quoted precision.

    Returns
    -------
    list of str: one line per quoted line not printed or per figure that differs.
    """
    plines = printed.splitlines()
    shapes = [shape(p) for p in plines]
    problems = []
    at = 0
    header: dict[str, set[int]] = {}
    cols: set[int] = set()
    for q in quoted.splitlines():
        if not q.strip() or q.strip() == "...":
            continue
        s = shape(q)
        try:
            k = shapes.index(s, at)
        except ValueError:
            problems.append(f"quoted line not printed: {q.strip()}")
            continue
        at = k + 1
        if q.lstrip().startswith("|-"):
            pass  # a table's separator row
        elif q.lstrip().startswith("|") and not _NUMBER.search(q):
            cols = header.setdefault(s, _timing_columns(q))
        elif not q.lstrip().startswith("|"):
            cols = set()
        qn = numbers(q, cols)
        pn = numbers(plines[k], cols)
        for (qv, timing), (pv, _) in zip(qn, pn, strict=True):
            if not timing and not agrees(qv, pv, rtol):
                problems.append(f"{qv} quoted, {pv} printed: {q.strip()}")
    return problems


def run_step(step: Step, workdir: Path, prelude: str, timeout: float = 1800) -> str:
    """Run one step's command in ``workdir``; return its stdout and stderr, interleaved."""
    command = step.command or ""
    if "replace" in step.notes:
        old, new = (p.strip() for p in step.notes["replace"].split("=>"))
        command = command.replace(old, new.strip('"'))
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env.setdefault("MPLBACKEND", "Agg")
    env["PYTHONUNBUFFERED"] = "1"  # stdout and stderr interleaved as a terminal shows them
    proc = subprocess.run(
        ["bash", "-e", "-o", "pipefail", "-c", prelude + command],
        cwd=workdir,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=timeout,
    )
    output = proc.stdout
    if proc.returncode != int(step.notes.get("status", 0)):
        raise RuntimeError(f"exit {proc.returncode}: {command}\n{output[-3000:]}")
    return output


def run_page(page: str, workdir: Path) -> list[str]:
    """Run one page's steps in ``workdir``; return its problems (``page:line: ...``)."""
    problems: list[str] = []
    prelude = ""
    for st in steps(page):
        if st.skip:
            if st.skip == "UNEXPLAINED":
                problems.append(f"{page}.md:{st.line}: output block with no command or note")
            continue
        where = f"{page}.md:{st.line}"
        try:
            if st.command is not None:
                printed = run_step(st, workdir, prelude)
                prelude += "".join(
                    ln + "\n" for ln in st.command.splitlines() if _ASSIGN.match(ln.strip())
                )
            else:
                printed = (workdir / st.notes["file"]).read_text(encoding="utf-8")
        except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
            problems.append(f"{where}: {exc}")
            continue
        if st.quoted is not None:
            rtol = float(st.notes["rtol"]) if "rtol" in st.notes else None
            problems += [f"{where}: {p}" for p in compare(st.quoted, printed, rtol)]
    return problems


if __name__ == "__main__":  # python tests/tutorial_check.py [WORKDIR [PAGE ...]]
    import tempfile

    work = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="tutorial-"))
    work.mkdir(parents=True, exist_ok=True)
    for p in sys.argv[2:] or PAGES:
        found = run_page(p, work)
        print(f"== {p}: {len(found)} problem(s) in {work}", flush=True)
        for line in found:
            print("  " + line, flush=True)
