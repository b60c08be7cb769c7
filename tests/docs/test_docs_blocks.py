"""The docs run: every ``bash`` and ``python`` block of the README and of docs/ is executed, in
order, page by page, in a fresh folder (a new data root), so a page cannot drift from the code.

A comment just before a block changes how it runs:
- ``<!-- docs: background URL -->`` starts it in the background and waits until URL answers
  (the block's server), stopping it when the page is done;
- ``<!-- docs: skip REASON -->`` leaves it out, with REASON (a real camera, a vehicle, a bucket
  of your own): the report counts these;
- ``<!-- docs: samples -->``: the block reads real camera files from ``$THERMCAP_SAMPLES``; it
  runs where they are, and the page is skipped, saying how to get them, where they are not;
- ``<!-- docs: output -->`` before a ``text`` block right after a block: what that block prints
  (its stdout), as the code printed it. The run compares them with figures and column widths
  set aside (a recording's bytes differ a little from run to run), so a page cannot show a
  table, a label or a verdict the code no longer prints; ``THERMCAP_DOCS_WRITE=1`` writes what
  the code printed into the page (how these blocks are made).

``pip install`` lines are not run: the tests run in the environment that installed them.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from tests.conftest import SAMPLES, SAMPLES_HOW

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
BLOCK = re.compile(r"(?:<!-- docs: (?P<mark>[a-z]+)(?: (?P<arg>[^\n]*?))? -->\s*\n)?"
                   r"```(?P<lang>[a-z]*)\n(?P<body>.*?)```", re.S)
RUN = {"bash", "python"}
WRITE = bool(os.environ.get("THERMCAP_DOCS_WRITE"))


@dataclass
class Block:
    page: Path
    line: int
    lang: str
    body: str
    mark: str | None
    arg: str | None
    shown: str | None = None  # the output the page shows for this block
    shown_span: tuple[int, int] | None = None  # where that output sits in the page's text
    end: int = 0  # where the block ends in the page's text

    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    text = page.read_text()
    out: list[Block] = []
    for m in BLOCK.finditer(text):
        if m.group("mark") == "output":
            assert m.group("lang") == "text" and out and text[out[-1].end:m.start()].strip() == "", \
                f"{page.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1}: an output block is a text block " \
                f"right after the block it shows"
            out[-1].shown, out[-1].shown_span = m.group("body"), m.span("body")
        elif m.group("lang") in RUN:
            b = Block(page, text[:m.start("lang")].count("\n") + 1, m.group("lang"), m.group("body"),
                      m.group("mark"), m.group("arg"))
            b.end = m.end()
            out.append(b)
    return out


def _shape(output: str, folder: Path) -> list[str]:
    """Output with what differs from run to run set aside: figures, the run's folder, the
    padding that aligns columns."""
    text = output.replace(str(folder), ".")
    text = re.sub(r"[0-9a-f]{8,}", "H", text)  # hashes, ids
    text = re.sub(r"\d+(?:[.,:]\d+)*", "0", text)
    return [re.sub(r"[ ─━═-]+", " ", line).strip() for line in text.splitlines() if line.strip()]


def _compare(b: Block, printed: str, folder: Path, written: dict[tuple[int, int], str]) -> None:
    if b.shown is None:
        return
    if WRITE:
        assert b.shown_span is not None
        written[b.shown_span] = printed.replace(str(folder), ".")
        return
    assert _shape(printed, folder) == _shape(b.shown, folder), \
        f"{b.where()}: the page shows output the code no longer prints (THERMCAP_DOCS_WRITE=1 writes it):\n" \
        f"printed:\n{printed}\nshown:\n{b.shown}"


def _write_outputs(page: Path, written: dict[tuple[int, int], str]) -> None:
    text = page.read_text()
    for (start, end), printed in sorted(written.items(), reverse=True):
        text = text[:start] + printed.rstrip("\n") + "\n" + text[end:]
    page.write_text(text)


def _shell(body: str) -> str:
    return "\n".join(":  # (installed)" if line.strip().startswith("pip install") else line
                     for line in body.splitlines())


def _wait_url(url: str, proc: subprocess.Popen, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"the background block exited ({proc.returncode}) before {url} answered")
        try:
            if httpx.get(url, timeout=2).status_code < 500:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.05)  # polling for the event, bounded by the deadline
    raise AssertionError(f"{url} did not answer in {timeout} s")


PAGES_WITH_BLOCKS = [p for p in PAGES if blocks(p)]


@pytest.mark.parametrize("page", PAGES_WITH_BLOCKS, ids=[str(p.relative_to(ROOT)) for p in PAGES_WITH_BLOCKS])
def test_page_runs(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run_page(page, tmp_path, monkeypatch)


def run_page(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
             environ: dict[str, str] | None = None) -> None:
    """Every block of ``page`` in order, in ``tmp_path``; shell blocks see ``environ`` (default
    this process's environment: a venv of the page's own puts its ``bin`` first on PATH)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("THERMCAP_ROOT", raising=False)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    env = {k: v for k, v in (environ or os.environ).items() if k != "THERMCAP_ROOT"}
    env["THERMCAP_SAMPLES"] = str(SAMPLES)
    env["COLUMNS"] = "100"  # the width tables are laid out for, in the page as in the run
    monkeypatch.setenv("COLUMNS", "100")
    written: dict[tuple[int, int], str] = {}
    if any(b.mark == "samples" for b in blocks(page)) and not SAMPLES.is_dir():
        pytest.skip(f"{page.name} reads real camera files, not present at {SAMPLES}: {SAMPLES_HOW}")
    background: list[subprocess.Popen] = []
    namespace: dict = {"__name__": "__docs__"}
    skipped = []
    try:
        for b in blocks(page):
            if b.mark == "skip":
                skipped.append(f"{b.where()}: {b.arg}")
                continue
            if b.lang == "python":
                printed = io.StringIO()
                try:
                    with contextlib.redirect_stdout(printed):
                        exec(compile(b.body, b.where(), "exec"), namespace)
                except Exception as exc:
                    raise AssertionError(f"{b.where()}: {type(exc).__name__}: {exc}") from exc
                _compare(b, printed.getvalue(), tmp_path, written)
                continue
            if b.mark == "background":
                proc = subprocess.Popen(["bash", "-c", _shell(b.body)], cwd=tmp_path, env=env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
                background.append(proc)
                _wait_url(b.arg or "", proc)
                continue
            done = subprocess.run(["bash", "-euo", "pipefail", "-c", _shell(b.body)], cwd=tmp_path, env=env,
                                  capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, f"{b.where()} exited {done.returncode}:\n{done.stdout[-2000:]}\n" \
                                         f"{done.stderr[-3000:]}"
            _compare(b, done.stdout, tmp_path, written)
    finally:
        for proc in background:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(20)
            except ProcessLookupError:
                pass
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    if written:
        _write_outputs(page, written)
    if skipped:
        print(f"{page.relative_to(ROOT)}: skipped {len(skipped)}: " + "; ".join(skipped))


def test_every_skip_says_why() -> None:
    for page in PAGES:
        for b in blocks(page):
            if b.mark == "skip":
                assert b.arg and len(b.arg) > 10, f"{b.where()}: a skip needs its reason"
            assert b.mark in (None, "skip", "background", "samples"), f"{b.where()}: unknown mark {b.mark!r}"
            assert b.shown is None or b.mark is None or b.mark == "samples", \
                f"{b.where()}: only a block that runs in the foreground shows its output"


def test_shown_output_is_held_to_what_the_code_prints(tmp_path: Path) -> None:
    """Figures, hashes, the run's folder and column padding may differ; a word may not."""
    shown = "format  per image  note\npng16      25 KB    recommended\nwritten ./a.tiff\n"
    same = f"format  per image   note\npng16       26 KB    recommended\nwritten {tmp_path}/a.tiff\n"
    assert _shape(same, tmp_path) == _shape(shown, tmp_path)
    for drifted in ("format  per image  note\npng16  25 KB  best\nwritten ./a.tiff\n",
                    "format  per image  note\npng16  25 KB  recommended\n"):
        assert _shape(drifted, tmp_path) != _shape(shown, tmp_path)
