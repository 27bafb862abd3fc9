"""The documentation: the site builds offline with warnings as errors, every code block of the README and of the
pages is marked, the marked blocks run and print what their excerpts say, and the figures are what the recorded
results and the builds say now.

Marks (the line right before a fenced block; docs/contributing.md, "The documentation"): ``<!-- run: test -->``
runs in ``make test``, ``<!-- run: matrix -->`` in ``make test-matrix``, ``<!-- run: never: WHY -->`` never (and
says why), ``<!-- file: NAME -->`` writes the block to NAME for the blocks after it, ``<!-- prints -->`` is an
excerpt of what the run block before it printed. A page's blocks run in order in one folder (``examples/`` linked
into it), ``sh`` through bash with the venv first on PATH, ``python`` as a script, each in a network namespace of
its own where one can be made (:func:`private_network`). The oracle is the real run: the commands' exit status and
what they print.
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from support import cli_server
from support.cli_server import write_client
from support.paths import ROOT

DOCS = ROOT / "docs"
VENV_BIN = Path(sys.executable).parent
MARK = re.compile(r"<!-- (?:run: (?P<run>test|matrix|never: .+)|file: (?P<file>\S+)|(?P<prints>prints)) -->")
FENCE = re.compile(r"^```(?P<info>\S*)(?:\s.*)?$")
SHELLS = ("sh", "bash")
TIMEOUT = {"test": 600, "matrix": 3600}


@dataclass(frozen=True)
class Block:
    """A fenced code block of a page and its mark (None when it has none)."""

    page: Path
    line: int
    lang: str
    text: str
    mark: str | None  # "test", "matrix", "never", "file", "prints"
    arg: str | None  # the file name of a "file" block, the reason of a "never" block

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def pages() -> list[Path]:
    """The README and every page of docs/ but the architecture page (docs/design.md: its blocks are diagrams and
    equations the other pages do not run) and the build."""
    found = [p for p in DOCS.rglob("*.md") if "_build" not in p.relative_to(DOCS).parts and p.name != "design.md"]
    return [ROOT / "README.md", *sorted(found)]


def _mark(line: str) -> tuple[str | None, str | None]:
    m = MARK.fullmatch(line.strip())
    if m is None:
        return None, None
    if m["run"]:
        kind = m["run"].split(":")[0]
        return kind, (m["run"].split(":", 1)[1].strip() if kind == "never" else None)
    return ("file", m["file"]) if m["file"] else ("prints", None)


def blocks(page: Path) -> list[Block]:
    """The fenced code blocks of ``page`` in order (MyST directives such as ```{toctree} are not code)."""
    lines = page.read_text("utf-8").splitlines()
    found, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), len(lines))
        info = m["info"]
        if not info.startswith("{"):
            mark, arg = _mark(lines[i - 1]) if i > 0 else (None, None)
            found.append(Block(page, i + 1, info, "\n".join(lines[i + 1 : end]) + "\n", mark, arg))
        i = end + 1
    return found


ALL = {page: blocks(page) for page in pages()}


def _ids(tier: str) -> list[Path]:
    return [page for page, bs in ALL.items() if any(b.mark == tier for b in bs)]


def test_every_code_block_is_marked_and_each_mark_fits_its_block():
    """No block is silently skipped: each says whether it runs (and in which tier), is a file, is an excerpt of what
    the block before printed, or never runs and why."""
    problems = []
    for bs in ALL.values():
        previous: Block | None = None
        for b in bs:
            if b.mark is None:
                problems.append(f"{b.where}: no mark (<!-- run: test|matrix|never: WHY -->, file: NAME, prints)")
            elif b.mark in ("test", "matrix") and b.lang not in (*SHELLS, "python"):
                problems.append(f"{b.where}: a {b.lang or 'plain'} block cannot run (mark it file: NAME or never)")
            elif b.mark == "prints" and (previous is None or previous.mark not in ("test", "matrix")):
                problems.append(f"{b.where}: an excerpt of what a block printed, after no block that runs")
            previous = b
    assert not problems, "\n".join(problems)


def test_the_readme_and_the_guide_run_something_in_make_test():
    """The README's quick start and the user guide are checked by running them, not only by being marked."""
    assert ROOT / "README.md" in _ids("test")
    guide = {p.name for p in _ids("test") if p.parent.name == "guide"}
    assert {"python.md", "specs.md", "firmware.md", "hil.md", "campaigns.md", "fixed_point.md"} <= guide, guide


LOOPBACK = "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo"


@functools.cache
def private_network() -> tuple[str, ...]:
    """A prefix that runs a command in a network namespace of its own, with nothing but a loopback that carries
    multicast (FIELD-NOTES), when this machine lets the suite make one (root: unshare -n).

    The pages' commands use the built-in scenarios as written, on their fixed ports (python-can's 43113, TCP 5760):
    in the host's namespace they would share them with each other, with the suite's other tests and with other
    checkouts' suites on this host (tests/support/net.py keeps every other test off them). In a namespace of its own
    each block has its ports to itself, and no network at all: nothing it runs can fetch anything."""
    unshare = shutil.which("unshare")
    prefix = (unshare or "unshare", "-n", "bash", "-c", f'{LOOPBACK} && exec "$0" "$@"')
    if unshare and subprocess.run([*prefix, "true"], capture_output=True).returncode == 0:
        return prefix
    return ()


def _run(block: Block, folder: Path, tier: str, cli: Path | None = None) -> str:
    """Run one block in ``folder`` (its ``gainlink`` commands through the server of ``cli``, a folder holding the
    client, when given); what it printed."""
    path = os.pathsep.join([*([str(cli)] if cli else []), str(VENV_BIN), os.environ.get("PATH", "")])
    env = {**os.environ, "PATH": path, "OPENBLAS_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    if block.lang == "python":
        script = folder / f"block_{block.line}.py"
        script.write_text(block.text)
        argv = [sys.executable, script.name]
    else:
        argv = ["bash", "-euo", "pipefail", "-c", block.text]
    proc = subprocess.run(
        [*private_network(), *argv],
        cwd=folder,
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,  # one stream, in the order it was written
        text=True,
        timeout=TIMEOUT[tier],
    )
    output = proc.stdout
    assert proc.returncode == 0, f"{block.where}: exited {proc.returncode}:\n{output[-4000:]}"
    return output


def _check_excerpt(block: Block, output: str) -> None:
    """Each line of the excerpt is part of a line of ``output``, in order."""
    lines, at = output.splitlines(), 0
    for want in (w.strip() for w in block.text.splitlines() if w.strip()):
        hit = next((i for i in range(at, len(lines)) if want in lines[i]), None)
        assert hit is not None, f"{block.where}: not printed (in this order): {want!r}\n--- printed:\n{output[-4000:]}"
        at = hit + 1


def run_page(page: Path, folder: Path, tiers: tuple[str, ...], cli: Path | None = None) -> None:
    """Run the blocks of ``page`` marked with one of ``tiers`` in order in ``folder``; write its files; check its
    excerpts against the block before each. ``cli``: a folder whose ``gainlink`` runs each command in a server
    (:func:`gainlink_server`)."""
    (folder / "examples").symlink_to(ROOT / "examples")
    output: str | None = None
    for b in ALL[page]:
        if b.mark == "file":
            (folder / str(b.arg)).write_text(b.text)
        elif b.mark == "prints":
            if output is not None:  # None: the block before runs in another tier
                _check_excerpt(b, output)
        else:
            output = _run(b, folder, str(b.mark), cli) if b.mark in tiers else None


#: CPU seconds each page's make-test blocks took (one process, warm caches, their ``gainlink`` commands through the
#: CLI server: measured by the server with wait4; its start, 3.3 CPU-s once per worker, aside): the order they start in
PAGE_CPU = {"docs/guide/python.md": 9, "README.md": 6, "docs/guide/firmware.md": 5, "docs/guide/fixed_point.md": 4,
            "docs/guide/hil.md": 3, "docs/guide/scheduled.md": 3, "docs/guide/campaigns.md": 2,
            "docs/guide/specs.md": 1, "docs/guide/troubleshooting.md": 1}  # fmt: skip


#: The pages' tests and the server's own: one worker runs them, so one CLI server serves them all (on every worker
#: that came to a page, each server's start cost its 3.3 CPU-s)
ON_THE_SERVER = pytest.mark.xdist_group("docs-cli-server")


def _page_params(tier: str) -> list:
    return [pytest.param(page, marks=[pytest.mark.slow(cpu=_page_cpu(page)), ON_THE_SERVER]) for page in _ids(tier)]


def _page_cpu(page: Path) -> float:
    return PAGE_CPU.get(str(page.relative_to(ROOT)), 0)


@pytest.fixture(scope="session")
def gainlink_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A folder whose ``gainlink`` runs each command as the console script would, in a fork of one process that
    imported the command line and its libraries once (``support/cli_server.py``: python-control's import alone is
    2.6 CPU-s a command). One per worker (session: a module's fixtures are made again each time a worker comes back
    to the module), and the tests that use it are one xdist group (ON_THE_SERVER), so one worker starts one; stopped
    at the worker's end, having waited for every command it ran, so that their CPU is the suite's (GAINLINK_TEST_CPU
    counts it in the worker's last test)."""
    folder = tmp_path_factory.mktemp("gainlink_cli")
    sock = folder / "cli.sock"
    write_client(folder / "gainlink", sock)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    server = subprocess.Popen([sys.executable, cli_server.__file__, str(sock)], stdin=subprocess.DEVNULL,
                              stdout=subprocess.PIPE, text=True, env=env, start_new_session=True)  # fmt: skip
    try:
        assert server.stdout is not None and server.stdout.readline().strip() == "ready", "the CLI server did not start"
        yield folder
    finally:
        server.terminate()
        try:
            server.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()


@pytest.mark.parametrize("page", _page_params("test"), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_blocks_of_a_page_run_as_written(page, tmp_path, gainlink_server):
    run_page(page, tmp_path, ("test",), gainlink_server)


@ON_THE_SERVER
def test_a_command_through_the_server_is_the_console_scripts(gainlink_server, pend, tmp_path):
    """The pages' ``gainlink`` (a fork of the CLI server) against the installed console script, the reader's: the
    same exit status, stdout, stderr and files for a command that writes in the caller's folder, a refusal (exit 2,
    one line, nothing written), a usage error and a help text."""
    simulate = ("simulate", pend, "--steps", "20", "--x0", "0", "0", "0.1", "0", "--out", "s.csv")
    cases = {("--version",): 0, simulate: 0, ("design", "missing.toml", "--out", "o"): 2, ("design", "--bogus"): 2,
             ("export", "--help"): 0}  # fmt: skip
    for argv, status in cases.items():
        outs = []
        for exe in (VENV_BIN / "gainlink", gainlink_server / "gainlink"):
            r = subprocess.run([str(exe), *map(str, argv)], cwd=tmp_path, capture_output=True, text=True,
                               timeout=120, stdin=subprocess.DEVNULL)  # fmt: skip
            written = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
            for p in tmp_path.iterdir():
                p.unlink()
            outs.append((r.returncode, r.stdout, r.stderr, written))
        assert outs[1] == outs[0], argv
        assert outs[0][0] == status and bool(outs[0][3]) == (argv[0] == "simulate"), outs[0]


@pytest.mark.matrix
@ON_THE_SERVER
@pytest.mark.parametrize("page", _ids("matrix"), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_long_blocks_of_a_page_run_as_written(page, tmp_path, gainlink_server):
    run_page(page, tmp_path, ("test", "matrix"), gainlink_server)


@pytest.mark.slow(cpu=13)
def test_the_site_builds_offline_with_warnings_as_errors(tmp_path):
    """``make docs``'s build (Sphinx, -W), in a network namespace without network where one can be made: nothing
    is fetched. Its pages include the architecture page, the API reference of every name of gl.__all__ and the
    command line's reference."""
    cmd = [*private_network(), sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "docs"]
    proc = subprocess.run(
        [*cmd, str(tmp_path / "html")], cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=600
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    html = tmp_path / "html"
    import gainlink

    api = (html / "api.html").read_text("utf-8")
    absent = [n for n in gainlink.__all__ if n not in ("hil", "campaign") and f'id="gainlink.{n}"' not in api]
    assert not absent, f"gl.__all__ names not in the API reference: {absent}"
    cli = (html / "cli.html").read_text("utf-8")
    assert all(f">{cmd}<" in cli for cmd in ("design", "firmware", "hil", "campaign", "mavlink")), "CLI reference"
    assert (html / "design.html").is_file() and (html / "guide" / "troubleshooting.html").is_file()


@pytest.mark.slow(cpu=31)  # the pendulum's images on every core built, in a fresh checkout (6 with them cached)
def test_the_figures_are_what_the_results_and_the_builds_say_now(capsys):
    """scripts/doc_figures.py --check: every figures block says what bench/results/ and the cached builds of the
    pendulum's images say now, including which recorded figures are older than the code they describe (run here, in
    the worker that has imported python-control already: as its own process, that import was half its 6.5 CPU-s)."""
    status = _doc_figures().main(["--check"])
    assert status == 0, capsys.readouterr().err


def _doc_figures():
    import importlib.util

    spec = importlib.util.spec_from_file_location("doc_figures", ROOT / "scripts" / "doc_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_recorded_figure_is_flagged_once_the_files_it_measures_change_and_only_then(tmp_path, monkeypatch):
    """The rule of scripts/doc_figures.py on a tree made here: a recording stores the sha256 of the files its
    benchmark measures; a change elsewhere leaves the figure as it is, a change to one of them flags it, in words
    that a later change does not alter (a figure flagged once stays flagged without another edit)."""
    figures = _doc_figures()
    monkeypatch.setattr(figures, "ROOT", tmp_path)
    for rel in ("hil/campaign/runner.py", "hil/loop/closed_loop.py", "bench/campaign.py", "runtime/api.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(f"# {rel}\n")
    stamp = {"from": "bench/campaign.py", "date": "2026-11-29", "cpus": 2, "load_average_at_record": 1.0}
    doc = {"recorded": {**stamp, "sources_sha256": figures.sources_digest("campaign")}}
    assert figures.staleness("campaign", doc) is None and "Older" not in figures.provenance(doc)
    (tmp_path / "runtime/api.py").write_text("# changed, but no campaign figure measures it\n")
    assert figures.staleness("campaign", doc) is None
    (tmp_path / "hil/campaign/runner.py").write_text("# changed\n")
    assert figures.staleness("campaign", doc) is not None
    flagged = " ".join(figures.provenance(doc).split())
    assert "**Older than the code it describes**" in flagged and "`scripts/bench.sh campaign`" in flagged
    (tmp_path / "hil/loop/closed_loop.py").write_text("# changed too\n")
    assert " ".join(figures.provenance(doc).split()) == flagged
    undated = {"recorded": stamp}
    assert figures.staleness("campaign", undated) is None
    assert "Not dated against the code it measures" in " ".join(figures.provenance(undated).split())
