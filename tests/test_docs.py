"""The examples in README.md and docs/*.md run, so a doc cannot rot.

A fenced block runs when the line right before its opening fence is one of (CONTRIBUTING.md,
"Examples in docs"):

    <!-- run -->                  run it
    <!-- run: server [ARGS] -->   run it while `vibsynth serve --output null ARGS` listens
    <!-- run: skip REASON -->     do not run it; the reason is required and shown as the skip

Shell blocks (sh, bash, shell) run with `bash -euo pipefail`; a line comment `# prints: TEXT`
asserts that TEXT appears in the block's output (stdout and stderr). Console blocks run each
`$ ` command on its own and compare the output shown under it, line by line in order: numbers
match any number, `…` matches any text, runs of spaces any spaces, and a command whose shown
output has a `vibsynth: error:` line must fail (any other must succeed). Python blocks of one
page run in one interpreter, in page order, sharing their variables (as a reader pasting them
into one session); `# prints: TEXT` works there too.

Each page gets its own temporary folder: the blocks run in `work/` with PATH starting with the
venv's bin, HOME and XDG_* inside the folder, no VIBSYNTH_* variable of the machine, and
VIBSYNTH_CONFIG pointing at a config that sets `osc.port` and the null audio output, and a
`.venv` link to the repository's (README's commands say `.venv/bin/vibsynth`). The
numbers 9570-9579 in a block are UDP ports: each is replaced by a free port of that page, 9570
by the page's test server (so docs show the default port a user types). Every block, and every
console command, has a timeout of 60 s.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VENV_BIN = ROOT / ".venv" / "bin" if (ROOT / ".venv" / "bin").is_dir() else Path(sys.executable).parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
TIMEOUT_S = 60.0

SHELL_LANGS = {"sh", "bash", "shell"}
CONSOLE_LANGS = {"console", "shell-session"}
PYTHON_LANGS = {"python", "py"}
RUNNABLE_LANGS = SHELL_LANGS | CONSOLE_LANGS | PYTHON_LANGS
# Pages being rewritten by other work: their blocks run once marked, but are not yet required
# to be marked. Remove a page from here when its examples are marked.
MARKING_PENDING: set[str] = set()

MARK = re.compile(r"^\s*<!--\s*run\b(?P<rest>.*?)-->\s*$")
FENCE = re.compile(r"^(?P<indent>\s*)(?P<fence>`{3,}|~{3,})(?P<info>.*)$")
CLOSING = re.compile(r"^\s*(`{3,}|~{3,})\s*$")
PORT = re.compile(r"\b957(\d)\b")
PRINTS = re.compile(r"#\s*prints:\s*(?P<text>.+?)\s*$")
NUMBER = re.compile(r"[-+]?\d[\d.,:]*")


class DocError(Exception):
    """A block that is marked wrongly (the runner refuses rather than silently skipping)."""


@dataclass
class Block:
    path: Path
    rel: str
    line: int  # line of the opening fence, 1-based
    lang: str
    text: str
    mode: str | None  # "run", "server", "skip" or None (unmarked)
    server_args: tuple[str, ...] = ()
    reason: str = ""

    @property
    def id(self) -> str:
        return f"{self.rel}:{self.line}"

    def header(self) -> str:
        return f"{self.id} ({self.lang} block)\n--- block ---\n{self.text.rstrip()}\n"


def _rel(path: Path) -> str:
    try:
        return path.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return path.name


def parse_marker(rest: str, where: str) -> tuple[str, tuple[str, ...], str]:
    """``rest`` is what follows ``run`` in the comment: "", ": server ARGS" or ": skip REASON"."""
    rest = rest.strip()
    if not rest:
        return "run", (), ""
    if not rest.startswith(":"):
        raise DocError(f"{where}: unknown marker '<!-- run{rest} -->' (use run, run: server [ARGS], run: skip REASON)")
    kind, _, arg = rest[1:].strip().partition(" ")
    arg = arg.strip()
    if kind == "server":
        return "server", tuple(shlex.split(arg)), ""
    if kind == "skip":
        if not arg:
            raise DocError(f"{where}: '<!-- run: skip -->' needs a reason")
        return "skip", (), arg
    raise DocError(f"{where}: unknown marker '<!-- run: {kind} -->' (use run, run: server [ARGS], run: skip REASON)")


def find_blocks(path: Path) -> list[Block]:
    """Every fenced block of a markdown file, with its marker; raises DocError on a bad marker."""
    rel = _rel(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    pending: tuple[int, str] | None = None  # (line, rest) of a marker waiting for its fence
    i = 0
    while i < len(lines):
        line = lines[i]
        marker = MARK.match(line)
        if marker:
            if pending:
                raise DocError(f"{rel}:{pending[0]}: marker not followed by a fenced block")
            pending = (i + 1, marker.group("rest"))
            i += 1
            continue
        opening = FENCE.match(line)
        if opening and "`" not in opening.group("info"):
            indent, fence = len(opening.group("indent")), opening.group("fence")
            lang = opening.group("info").strip().split(" ")[0].lower()
            body: list[str] = []
            j = i + 1
            while j < len(lines):
                closing = CLOSING.match(lines[j])
                if closing and closing.group(1).startswith(fence):
                    break
                strip = len(lines[j]) - len(lines[j].lstrip(" "))
                body.append(lines[j][min(indent, strip) :])  # a fence indented in a list item
                j += 1
            mode, args, reason = None, (), ""
            if pending:
                if pending[0] != i:
                    raise DocError(f"{rel}:{pending[0]}: the marker must be on the line right before the fence")
                mode, args, reason = parse_marker(pending[1], f"{rel}:{pending[0]}")
                pending = None
                if mode != "skip" and lang not in RUNNABLE_LANGS:
                    allowed = ", ".join(sorted(RUNNABLE_LANGS))
                    raise DocError(f"{rel}:{i + 1}: a runnable block must be one of {allowed}, not '{lang or 'none'}'")
            blocks.append(Block(path, rel, i + 1, lang, "\n".join(body) + "\n", mode, args, reason))
            i = j + 1
            continue
        if pending and line.strip():
            raise DocError(f"{rel}:{pending[0]}: marker not followed by a fenced block")
        i += 1
    if pending:
        raise DocError(f"{rel}:{pending[0]}: marker not followed by a fenced block")
    return blocks


# --------------------------------------------------------------------------- environment


_PORTS_GIVEN: set[int] = set()
_PORTS_LOCK = threading.Lock()


def free_port() -> int:
    """A free UDP port on 127.0.0.1, never the same twice in a session (pages run concurrently)."""
    with _PORTS_LOCK:
        while True:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                sock.bind(("127.0.0.1", 0))
                port = int(sock.getsockname()[1])
            if port not in _PORTS_GIVEN:
                _PORTS_GIVEN.add(port)
                return port


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def run_process(argv: list[str], page: Page, *, stdin: str | None = None, timeout: float = TIMEOUT_S):
    """Run argv in the page's folder and environment; (returncode or None on timeout, stdout, stderr).

    The process gets its own process group, killed afterwards, so nothing a block started in
    the background outlives it.
    """
    proc = subprocess.Popen(
        argv,
        cwd=page.work,
        env=page.env,
        stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(stdin, timeout=timeout)
        code: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        _kill_group(proc)
        out, err = proc.communicate()
        code = None
    _kill_group(proc)
    return code, out, err


@dataclass
class Page:
    """One page's temporary folder, environment, ports and (at most one) test server."""

    rel: str
    root: Path
    banks: Path | None = None  # a bank cache shared by the pages (their XDG_CACHE_HOME links to it)
    ports: dict[int, int] = field(default_factory=dict)
    server: subprocess.Popen | None = None
    server_args: tuple[str, ...] | None = None
    python_results: dict[int, dict] | None = None

    def __post_init__(self) -> None:
        self.work = self.root / "work"
        for folder in ("work", "home", "config", "data", "cache", "state", "runtime"):
            (self.root / folder).mkdir(parents=True, exist_ok=True)
        if self.banks is not None:
            # The noise bank a page's commands build (keyed by its settings) is the same on every page:
            # built once for the session, not once a page. Nothing else of the cache is shared.
            self.banks.mkdir(parents=True, exist_ok=True)
            (self.root / "cache" / "vibsynth").mkdir(exist_ok=True)
            (self.root / "cache" / "vibsynth" / "banks").symlink_to(self.banks, target_is_directory=True)
        os.chmod(self.root / "runtime", 0o700)
        # README's commands say .venv/bin/vibsynth, as typed in a checkout
        (self.work / ".venv").symlink_to(VENV_BIN.parent, target_is_directory=True)
        self.port(9570)
        self.config = self.root / "vibsynth-config.yaml"
        self.config.write_text(
            f'# written by tests/test_docs.py\nosc:\n  port: {self.ports[9570]}\naudio:\n  backend: "null"\n',
            encoding="utf-8",
        )
        env = {k: v for k, v in os.environ.items() if not k.startswith(("VIBSYNTH_", "XDG_"))}
        env.update(
            PATH=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '/usr/bin:/bin')}",
            HOME=str(self.root / "home"),
            XDG_CONFIG_HOME=str(self.root / "config"),
            XDG_DATA_HOME=str(self.root / "data"),
            XDG_CACHE_HOME=str(self.root / "cache"),
            XDG_STATE_HOME=str(self.root / "state"),
            XDG_RUNTIME_DIR=str(self.root / "runtime"),
            VIBSYNTH_CONFIG=str(self.config),
            JACK_NO_START_SERVER="1",
            MPLBACKEND="Agg",
            PYTHONDONTWRITEBYTECODE="1",
            PYTHONUNBUFFERED="1",
            COLUMNS="120",
        )
        env.pop("PYTHONPATH", None)
        self.env = env

    def port(self, documented: int) -> int:
        if documented not in self.ports:
            self.ports[documented] = free_port()
        return self.ports[documented]

    def substitute(self, text: str) -> str:
        """The documented ports 9570-9579 become this page's ports."""
        return PORT.sub(lambda m: str(self.port(int(m.group(0)))), text)

    # -- the test server
    def ensure_server(self, args: tuple[str, ...]) -> None:
        if self.server is not None and self.server.poll() is None and self.server_args == args:
            return
        self.stop_server()
        log = open(self.root / "server.log", "w", encoding="utf-8")  # noqa: SIM115 (kept open by the server)
        argv = [str(VENV_BIN / "vibsynth"), "serve", "--output", "null", *(self.substitute(a) for a in args)]
        self.server = subprocess.Popen(
            argv, cwd=self.work, env=self.env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        self.server_args = args
        # ready once its banner names the OSC socket (printed after binding; a ping would not
        # work for every server: with osc.reply_port the pong goes elsewhere)
        deadline = time.monotonic() + TIMEOUT_S
        while "vibsynth: OSC on udp://" not in self.server_log():
            if self.server.poll() is not None:
                raise AssertionError(f"{shlex.join(argv)} exited ({self.server.returncode}):\n{self.server_log()}")
            if time.monotonic() > deadline:
                raise AssertionError(f"{shlex.join(argv)} did not start within {TIMEOUT_S} s:\n{self.server_log()}")
            time.sleep(0.05)

    def server_log(self) -> str:
        path = self.root / "server.log"
        return path.read_text(encoding="utf-8", errors="replace") if path.exists() else ""

    def stop_server(self) -> None:
        if self.server is None:
            return
        if self.server.poll() is None:
            os.killpg(self.server.pid, signal.SIGTERM)
            try:
                self.server.wait(10)
            except subprocess.TimeoutExpired:
                _kill_group(self.server)
                self.server.wait()
        self.server = None
        self.server_args = None


class Pages:
    """The pages' environments. Pages are independent: ``start`` runs several at once."""

    def __init__(self, tmp: Path, workers: int = 2) -> None:
        self.tmp = tmp
        self.pages: dict[str, Page] = {}
        self.lock = threading.Lock()
        self.executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="docs")
        self.jobs: dict[str, Future[dict[str, str | None]]] = {}

    def get(self, block: Block) -> Page:
        with self.lock:
            if block.rel not in self.pages:
                self.pages[block.rel] = Page(block.rel, self.tmp / re.sub(r"\W", "_", block.rel), self.tmp / "banks")
            return self.pages[block.rel]

    def start(self, blocks: list[Block]) -> None:
        """Run each page's blocks in page order, pages side by side; results via ``result``."""
        for rel in dict.fromkeys(b.rel for b in blocks):
            if rel not in self.jobs:
                page_blocks = [b for b in blocks if b.rel == rel]
                self.jobs[rel] = self.executor.submit(self._run_page, page_blocks)

    def _run_page(self, page_blocks: list[Block]) -> dict[str, str | None]:
        reports: dict[str, str | None] = {}
        try:
            for block in page_blocks:
                if block.mode != "skip":
                    try:
                        reports[block.id] = run_block(block, self, page_blocks)
                    except Exception as exc:  # a DocError or a server that did not start
                        reports[block.id] = f"{block.header()}--- the runner failed ---\n{exc}"
        finally:
            if page_blocks:
                self.get(page_blocks[0]).stop_server()
        return reports

    def result(self, block: Block, page_blocks: list[Block]) -> str | None:
        self.start(page_blocks)
        return self.jobs[block.rel].result()[block.id]

    def close(self) -> None:
        self.executor.shutdown(wait=True, cancel_futures=True)
        for page in self.pages.values():
            page.stop_server()


# --------------------------------------------------------------------------- running blocks


def _report(block: Block, page: Page, what: str, out: str = "", err: str = "") -> str:
    text = f"{block.header()}--- {what} ---\n"
    if out:
        text += f"--- stdout ---\n{out.rstrip()}\n"
    if err:
        text += f"--- stderr ---\n{err.rstrip()}\n"
    if page.server is not None:
        args = shlex.join(page.server_args or ())
        text += f"--- test server ({args}) log ---\n{page.server_log().rstrip()[-3000:]}\n"
    return text


def expected_prints(text: str) -> list[str]:
    return [m.group("text") for line in text.splitlines() if (m := PRINTS.search(line))]


def check_prints(block: Block, page: Page, code: str, out: str, err: str) -> str | None:
    missing = [text for text in expected_prints(code) if text not in out and text not in err]
    if missing:
        return _report(block, page, f"output lacks: {missing!r}", out, err)
    return None


def run_shell(block: Block, page: Page) -> str | None:
    """None when the block ran as documented, else the report of what went wrong."""
    script = page.substitute(block.text)
    if not any(line.strip() and not line.lstrip().startswith("#") for line in script.splitlines()):
        return _report(block, page, "the block has no command")
    code, out, err = run_process(["bash", "-euo", "pipefail", "-c", script], page)
    if code is None:
        return _report(block, page, f"timed out after {TIMEOUT_S} s", out, err)
    if code != 0:
        return _report(block, page, f"exit code {code}", out, err)
    return check_prints(block, page, script, out, err)


def parse_console(text: str) -> list[tuple[str, list[str]]]:
    """[(command, shown output lines)] of a `$ `-prompted block."""
    steps: list[tuple[str, list[str]]] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            command = line[2:]
            while command.endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command + "\n" + lines[i]
            steps.append((command, []))
        elif line.strip():
            if not steps:
                raise DocError(f"output before the first '$ ' command: {line!r}")
            steps[-1][1].append(line)
        i += 1
    return steps


def line_pattern(shown: str) -> re.Pattern[str]:
    """A shown output line as a pattern: numbers match any number, `…` any text, spaces any spaces."""
    parts: list[str] = []
    for piece in re.split(r"(…|\s+)", shown.strip()):
        if piece == "…":
            parts.append(".*")
        elif piece.isspace():
            parts.append(r"\s+")
        elif piece:
            position = 0
            for number in NUMBER.finditer(piece):
                parts.append(re.escape(piece[position : number.start()]))
                parts.append(NUMBER.pattern)
                position = number.end()
            parts.append(re.escape(piece[position:]))
    return re.compile("".join(parts))


def match_output(shown: list[str], actual: str) -> str | None:
    """None when every shown line matches an actual line, in order; else the first that does not."""
    lines = actual.splitlines()
    position = 0
    for expected in shown:
        if expected.strip() in ("...", "…"):
            continue
        pattern = line_pattern(expected)
        for k in range(position, len(lines)):
            if pattern.search(lines[k]):
                position = k + 1
                break
        else:
            return expected
    return None


def run_console(block: Block, page: Page) -> str | None:
    steps = parse_console(page.substitute(block.text))
    if not steps:
        return _report(block, page, "the console block has no '$ ' command")
    for command, shown in steps:
        code, out, err = run_process(["bash", "-euo", "pipefail", "-c", command], page)
        if code is None:
            return _report(block, page, f"$ {command}: timed out after {TIMEOUT_S} s", out, err)
        should_fail = any(line.startswith("vibsynth: error:") for line in shown)
        if should_fail and code == 0:
            return _report(block, page, f"$ {command}: succeeded, but the block shows an error", out, err)
        if not should_fail and code != 0:
            return _report(block, page, f"$ {command}: exit code {code}", out, err)
        unmatched = match_output(shown, out + err)
        if unmatched is not None:
            return _report(block, page, f"$ {command}: no output line matches {unmatched!r}", out, err)
    return None


# A page's Python blocks run in one interpreter, in order, sharing a namespace.
PYTHON_DRIVER = r"""
import contextlib, io, json, signal, sys, traceback
blocks = json.load(open(sys.argv[1], encoding="utf-8"))
results = {}
namespace = {"__name__": "__main__"}
failed = None

def alarm(signum, frame):
    raise TimeoutError("block timed out")

signal.signal(signal.SIGALRM, alarm)
for block in blocks:
    if failed is not None:
        results[block["line"]] = {"ok": False, "out": "", "err": f"not run: the block at {failed} failed"}
        continue
    out, err = io.StringIO(), io.StringIO()
    ok = True
    signal.alarm(int(block["timeout"]))
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            exec(compile("\n" * block["line"] + block["code"], block["file"], "exec"), namespace)
    except BaseException:
        ok = False
        err.write(traceback.format_exc())
        failed = block["id"]
    finally:
        signal.alarm(0)
    results[block["line"]] = {"ok": ok, "out": out.getvalue(), "err": err.getvalue()}
json.dump(results, open(sys.argv[2], "w", encoding="utf-8"))
"""


def run_python_page(blocks: list[Block], page: Page) -> dict[int, dict]:
    source = page.root / "python-blocks.json"
    target = page.root / "python-results.json"
    source.write_text(
        json.dumps(
            [
                {"id": b.id, "file": b.rel, "line": b.line, "code": page.substitute(b.text), "timeout": TIMEOUT_S}
                for b in blocks
            ]
        ),
        encoding="utf-8",
    )
    target.unlink(missing_ok=True)
    code, out, err = run_process(
        [str(VENV_BIN / "python"), "-c", PYTHON_DRIVER, str(source), str(target)],
        page,
        timeout=TIMEOUT_S * len(blocks) + 10,
    )
    if code != 0 or not target.exists():
        failure = {"ok": False, "out": out, "err": f"the Python session failed (exit code {code}):\n{err}"}
        return {b.line: failure for b in blocks}
    return {int(line): result for line, result in json.loads(target.read_text(encoding="utf-8")).items()}


def run_python(block: Block, page: Page, page_blocks: list[Block]) -> str | None:
    if page.python_results is None:
        python_blocks = [b for b in page_blocks if b.lang in PYTHON_LANGS and b.mode in ("run", "server")]
        servers = {b.server_args for b in python_blocks if b.mode == "server"}
        if len(servers) > 1:
            raise DocError(f"{block.rel}: its Python blocks ask for different servers: {sorted(servers)}")
        if servers:
            page.ensure_server(servers.pop())
        page.python_results = run_python_page(python_blocks, page)
    result = page.python_results[block.line]
    if not result["ok"]:
        return _report(block, page, "raised", result["out"], result["err"])
    return check_prints(block, page, page.substitute(block.text), result["out"], result["err"])


def run_block(block: Block, pages: Pages, page_blocks: list[Block]) -> str | None:
    """Run one marked block; None when it ran as documented, else a report naming file:line."""
    page = pages.get(block)
    if block.mode == "server" and block.lang not in PYTHON_LANGS:
        page.ensure_server(block.server_args)
    if block.lang in PYTHON_LANGS:
        return run_python(block, page, page_blocks)
    if block.lang in CONSOLE_LANGS:
        return run_console(block, page)
    return run_shell(block, page)


# --------------------------------------------------------------------------- the tests


def _all_blocks() -> tuple[list[Block], list[str]]:
    blocks: list[Block] = []
    errors: list[str] = []
    for path in PAGES:
        try:
            blocks += find_blocks(path)
        except DocError as exc:
            errors.append(str(exc))
    return blocks, errors


BLOCKS, MARKER_ERRORS = _all_blocks()
MARKED = [b for b in BLOCKS if b.mode is not None]


@pytest.fixture(scope="module")
def pages(tmp_path_factory, request):
    registry = Pages(tmp_path_factory.mktemp("docs"))
    selected = [
        item.callspec.params["block"]
        for item in request.session.items
        if getattr(item, "callspec", None) is not None and isinstance(item.callspec.params.get("block"), Block)
    ]
    chosen = {b.rel for b in selected}
    registry.start([b for b in MARKED if b.rel in chosen])  # whole pages, two at a time, from the start
    yield registry
    registry.close()


def test_markers_are_valid():
    assert not MARKER_ERRORS, "\n".join(MARKER_ERRORS)


def test_every_example_is_marked():
    """A shell, console or Python block either runs or says why it cannot."""
    unmarked = [
        b.id
        for b in BLOCKS
        if b.mode is None
        and (b.lang in RUNNABLE_LANGS or (not b.lang and b.text.startswith("$ ")))  # a console block without its tag
        and b.rel not in MARKING_PENDING
    ]
    assert not unmarked, f"mark these <!-- run -->, <!-- run: server --> or <!-- run: skip REASON -->: {unmarked}"


@pytest.mark.parametrize("block", MARKED, ids=[b.id for b in MARKED])
def test_doc_example(block: Block, pages: Pages):
    if block.mode == "skip":
        pytest.skip(f"{block.id}: {block.reason}")
    failure = pages.result(block, [b for b in MARKED if b.rel == block.rel])
    if failure:
        pytest.fail(failure, pytrace=False)


def test_python_page_covers_every_topic():
    """docs/python.md shows each public entry point (and test_doc_example runs them)."""
    text = "\n".join(b.text for b in BLOCKS if b.rel == "docs/python.md" and b.mode in ("run", "server"))
    for needle in (
        "vibsynth.analyze",
        "vibsynth.synthesize",
        "vibsynth.render",
        "vibsynth.Engine",
        "load_config",
        "vibsynth.Preset",
        "vibsynth.Client",
        ".get(",
        ".status()",
        "client.at(",
        "NoReplyError",
        "save_preset",
    ):
        assert needle in text, needle


def test_python_page_wrote_its_files(pages: Pages):
    """docs/python.md's examples write a WAV and a preset into the folder they run in."""
    if "docs/python.md" in pages.jobs:
        pages.jobs["docs/python.md"].result()
    page = pages.pages.get("docs/python.md")
    if page is None or page.python_results is None:
        pytest.skip("docs/python.md's examples were not run in this session (deselected)")
    assert all(result["ok"] for result in page.python_results.values())
    assert (page.work / "texture.wav").stat().st_size > 48000
    assert "name: my-silk" in (page.work / "my-silk.yaml").read_text(encoding="utf-8")


# --------------------------------------------------------------------------- the runner's own tests


def _page_of(tmp_path: Path, text: str) -> tuple[list[Block], Pages]:
    doc = tmp_path / "planted.md"
    doc.write_text(text, encoding="utf-8")
    return find_blocks(doc), Pages(tmp_path / "run")


def test_runner_reports_a_failing_shell_block(tmp_path):
    blocks, registry = _page_of(tmp_path, "# Planted\n\ntext\n\n<!-- run -->\n```sh\necho before\nfalse\n```\n")
    (block,) = blocks
    report = run_block(block, registry, blocks)
    assert report is not None
    assert report.startswith("planted.md:6 (sh block)")
    assert "exit code 1" in report and "echo before" in report and "--- stdout ---\nbefore" in report


def test_runner_reports_a_missing_print_and_a_console_mismatch(tmp_path):
    blocks, registry = _page_of(
        tmp_path,
        "<!-- run -->\n```sh\necho 'hello 12'  # prints: hello 13\n```\n\n"
        "<!-- run -->\n```console\n$ echo 'rate 48000 Hz, block 128'\nrate 1 Hz, block … \n$ echo two\nthree\n```\n\n"
        "<!-- run -->\n```console\n$ vibsynth --version\nvibsynth: error: nothing\n```\n",
    )
    prints, console, should_fail = blocks
    assert "output lacks: ['hello 13']" in (run_block(prints, registry, blocks) or "")
    report = run_block(console, registry, blocks) or ""
    assert report.startswith("planted.md:7 (console block)") and "no output line matches 'three'" in report
    assert "succeeded, but the block shows an error" in (run_block(should_fail, registry, blocks) or "")


def test_runner_reports_a_failing_python_block_and_skips_the_rest(tmp_path):
    blocks, registry = _page_of(
        tmp_path,
        "<!-- run -->\n```python\nx = 1\nprint('x is', x)  # prints: x is 1\n```\n\n"
        "<!-- run -->\n```python\nprint(undefined_name)\n```\n\n"
        "<!-- run -->\n```python\nprint(x)\n```\n",
    )
    first, second, third = blocks
    assert run_block(first, registry, blocks) is None
    report = run_block(second, registry, blocks) or ""
    assert report.startswith("planted.md:8 (python block)") and "NameError: name 'undefined_name'" in report
    assert 'File "planted.md", line 9' in report  # tracebacks name the page's own lines
    assert "not run: the block at planted.md:8 failed" in (run_block(third, registry, blocks) or "")


def test_runner_runs_blocks_in_an_isolated_environment_against_the_test_server(tmp_path):
    blocks, registry = _page_of(
        tmp_path,
        '<!-- run: server -->\n```sh\necho "$HOME $XDG_CONFIG_HOME $VIBSYNTH_CONFIG" > where.txt\n'
        "vibsynth send /vibsynth/ping 7 --port 9570 --wait-reply 1  # prints: /vibsynth/pong i 7\n```\n",
    )
    try:
        assert run_block(blocks[0], registry, blocks) is None
        page = registry.pages["planted.md"]
        where = (page.work / "where.txt").read_text(encoding="utf-8")
        assert where.split() == [str(page.root / "home"), str(page.root / "config"), str(page.config)]
        assert page.ports[9570] != 9570 or free_port() == 9570
    finally:
        registry.close()


def test_runner_refuses_bad_markers(tmp_path):
    for text, message in (
        ("<!-- run: skip -->\n```sh\ntrue\n```\n", "needs a reason"),
        ("<!-- run: later -->\n```sh\ntrue\n```\n", "unknown marker"),
        ("<!-- run -->\n```yaml\na: 1\n```\n", "a runnable block must be one of"),
        ("<!-- run -->\n\nsome text\n```sh\ntrue\n```\n", "marker not followed by a fenced block"),
    ):
        doc = tmp_path / "bad.md"
        doc.write_text(text, encoding="utf-8")
        with pytest.raises(DocError, match=message):
            find_blocks(doc)


def test_console_patterns():
    assert match_output(["up 42 s, load 0.9 % (peak 2.1 %)"], "x\nup 7 s, load 12.5 % (peak 30 %)\n") is None
    assert match_output(["a … z"], "a anything at all z") is None
    assert match_output(["channel 1 -"], "channel 2 velvet") == "channel 1 -"
    assert match_output(["first", "second"], "second\nfirst\n") == "second"
