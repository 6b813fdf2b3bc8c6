"""No POSIX-only (or Windows-only) call unguarded in ``vibsynth/`` (issue 32, item 5).

The wheels install on Linux, macOS and Windows, so a module must import and run on each. This test
walks the AST of every module and fails on

* an import of a module only one family of systems has (``fcntl``, ``termios``, ``resource``,
  ``pwd``, ``grp``, ``pty``, ``tty``, ``posix``, ... and ``msvcrt``, ``winreg``, ...), at module
  level or inside a function;
* a use of an ``os`` name Windows lacks (``os.fork``, ``os.setsid``, ``os.killpg``, ``os.getuid``,
  ``os.getpgid``, ``os.setpgid``, ``os.sched_*``, ``os.SCHED_*``, ...) or of a POSIX-only signal
  (``signal.SIGKILL``, ``SIGHUP``, ``SIGUSR1``, ``SIGALRM``, ``SIGCHLD``, ...; ``SIGINT`` and
  ``SIGTERM`` exist on Windows) or signal function (``signal.alarm``, ``setitimer``, ...),

unless it sits under a platform check (``if sys.platform ...``, ``if os.name ...``,
``if hasattr(os, ...)``, ``platform.system()``; either branch, or after such an ``if`` that
returns or raises), or inside the body of a ``try`` whose handler catches what the missing name
raises there: ``AttributeError`` for a name of ``os``/``signal``, ``ImportError`` for a module
(or a broader class). ``except OSError`` alone is not a guard: on Windows the name is missing,
which is an ``AttributeError``. ``getattr(os, "name", None)`` is not an attribute access and is
never flagged.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vibsynth"

#: Modules that exist on only one family of systems.
PLATFORM_MODULES = {
    # POSIX only
    "fcntl",
    "termios",
    "resource",
    "pwd",
    "grp",
    "pty",
    "tty",
    "posix",
    "syslog",
    "crypt",
    "spwd",
    "nis",
    "readline",
    # Windows only
    "msvcrt",
    "winreg",
    "winsound",
    "_winapi",
    "nt",
}
#: Names of ``os`` that Windows does not have (prefixes end with ``*``).
POSIX_OS = {
    "fork",
    "forkpty",
    "setsid",
    "getsid",
    "killpg",
    "getuid",
    "geteuid",
    "getgid",
    "getegid",
    "getgroups",
    "setuid",
    "setgid",
    "seteuid",
    "setegid",
    "getpgid",
    "setpgid",
    "getpgrp",
    "setpgrp",
    "getpwnam",
    "nice",
    "getpriority",
    "setpriority",
    "mkfifo",
    "mknod",
    "chown",
    "lchown",
    "fchown",
    "getloadavg",
    "sync",
    "wait3",
    "wait4",
    "pipe2",
    "openpty",
    "ttyname",
    "uname",
    "sysconf",
    "pathconf",
    "fpathconf",
    "statvfs",
    "fstatvfs",
    "posix_spawn",
    "posix_spawnp",
    "register_at_fork",
    "memfd_create",
    "initgroups",
    "O_NONBLOCK",
    "WNOHANG",
    "sched_*",
    "SCHED_*",
}
#: Signals Windows has (every other ``signal.SIG*`` is POSIX only).
WINDOWS_SIGNALS = {"SIGABRT", "SIGFPE", "SIGILL", "SIGINT", "SIGSEGV", "SIGTERM", "SIGBREAK", "SIG_DFL", "SIG_IGN"}
#: Functions of ``signal`` that Windows does not have.
POSIX_SIGNAL_FUNCTIONS = {
    "alarm",
    "pause",
    "setitimer",
    "getitimer",
    "siginterrupt",
    "pthread_kill",
    "pthread_sigmask",
    "sigpending",
    "sigwait",
    "sigwaitinfo",
    "sigtimedwait",
    "ITIMER_REAL",
    "ITIMER_VIRTUAL",
    "ITIMER_PROF",
}
#: Exception classes that catch the failure on the other system, by what failed.
CATCHES_NAME = {"AttributeError", "Exception", "BaseException"}
CATCHES_IMPORT = {"ImportError", "ModuleNotFoundError", "Exception", "BaseException"}


def _platform_only_name(module: str, name: str) -> bool:
    """Is ``module.name`` missing on some supported system?"""
    if module == "os":
        return name in POSIX_OS or any(p.endswith("*") and name.startswith(p[:-1]) for p in POSIX_OS)
    if module == "signal":
        if name in POSIX_SIGNAL_FUNCTIONS:
            return True
        return name.startswith("SIG") and name not in WINDOWS_SIGNALS
    return False


def _is_platform_check(test: ast.expr) -> bool:
    """Does this condition ask which system this is (``sys.platform``, ``os.name``, ``hasattr``...)?"""
    for node in ast.walk(test):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if (node.value.id, node.attr) in {("sys", "platform"), ("os", "name")}:
                return True
            if node.value.id == "platform" and node.attr in {"system", "platform"}:
                return True
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "hasattr":
            return True
        if isinstance(node, ast.Name) and node.id in {"WINDOWS", "POSIX", "IS_WINDOWS", "IS_POSIX"}:
            return True
    return False


def _caught(handlers: list[ast.ExceptHandler], wanted: set[str]) -> bool:
    for handler in handlers:
        if handler.type is None:
            return True
        types = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
        for t in types:
            name = t.attr if isinstance(t, ast.Attribute) else t.id if isinstance(t, ast.Name) else None
            if name in wanted:
                return True
    return False


def _exits(body: list[ast.stmt]) -> bool:
    return bool(body) and isinstance(body[-1], (ast.Return, ast.Raise, ast.Continue, ast.Break))


class _Finder(ast.NodeVisitor):
    """Collect ``(line, what)`` for each unguarded platform-only import or name."""

    def __init__(self) -> None:
        self.found: list[tuple[int, str]] = []
        self._platform = 0  # depth of enclosing platform checks
        self._catch_name = 0  # depth of enclosing try bodies that catch AttributeError
        self._catch_import = 0  # ... ImportError

    # guards -------------------------------------------------------------------------------------
    def visit_If(self, node: ast.If) -> None:
        self.visit(node.test)
        if _is_platform_check(node.test):
            self._platform += 1
            self._statements(node.body)
            self._statements(node.orelse)
            self._platform -= 1
        else:
            self._statements(node.body)
            self._statements(node.orelse)

    def visit_IfExp(self, node: ast.IfExp) -> None:
        guarded = _is_platform_check(node.test)
        self.visit(node.test)
        self._platform += guarded
        self.visit(node.body)
        self.visit(node.orelse)
        self._platform -= guarded

    def visit_Try(self, node: ast.Try) -> None:
        name, module = _caught(node.handlers, CATCHES_NAME), _caught(node.handlers, CATCHES_IMPORT)
        self._catch_name += name
        self._catch_import += module
        self._statements(node.body)
        self._catch_name -= name
        self._catch_import -= module
        for handler in node.handlers:
            self._statements(handler.body)
        self._statements(node.orelse)
        self._statements(node.finalbody)

    visit_TryStar = visit_Try

    def _statements(self, body: list[ast.stmt]) -> None:
        """Visit a block; after ``if <platform check>: return``, the rest of the block is guarded."""
        raised = 0
        for stmt in body:
            self.visit(stmt)
            if isinstance(stmt, ast.If) and _is_platform_check(stmt.test) and _exits(stmt.body) and not raised:
                self._platform += 1
                raised = 1
        self._platform -= raised

    def generic_visit(self, node: ast.AST) -> None:
        for _field, value in ast.iter_fields(node):
            if isinstance(value, list) and value and all(isinstance(v, ast.stmt) for v in value):
                self._statements(value)  # every block: function bodies, loops, with
            elif isinstance(value, list):
                for item in value:
                    if isinstance(item, ast.AST):
                        self.visit(item)
            elif isinstance(value, ast.AST):
                self.visit(value)

    # findings -----------------------------------------------------------------------------------
    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            if alias.name.split(".")[0] in PLATFORM_MODULES and not (self._platform or self._catch_import):
                self.found.append((node.lineno, f"import {alias.name}"))

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        module = node.module or ""
        if node.level or self._platform:
            return
        if module.split(".")[0] in PLATFORM_MODULES and not self._catch_import:
            self.found.append((node.lineno, f"from {module} import ..."))
        elif module in {"os", "signal"} and not self._catch_import:
            for alias in node.names:
                if _platform_only_name(module, alias.name):
                    self.found.append((node.lineno, f"from {module} import {alias.name}"))

    def visit_Attribute(self, node: ast.Attribute) -> None:
        if (
            isinstance(node.value, ast.Name)
            and _platform_only_name(node.value.id, node.attr)
            and not (self._platform or self._catch_name)
        ):
            self.found.append((node.lineno, f"{node.value.id}.{node.attr}"))
        self.generic_visit(node)


def unguarded(source: str) -> list[tuple[int, str]]:
    """The unguarded platform-only imports and names of a module's source, as ``(line, what)``."""
    finder = _Finder()
    finder.visit(ast.parse(source))
    return sorted(set(finder.found))


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_every_module_of_the_package_runs_on_every_system():
    assert len(_modules()) > 100  # the walk found the package
    findings = [
        f"{path.relative_to(PACKAGE.parent)}:{line}: {what}"
        for path in _modules()
        for line, what in unguarded(path.read_text(encoding="utf-8"))
    ]
    assert not findings, "platform-only calls without a platform check or a try that catches them:\n" + "\n".join(
        findings
    )


# The checker itself, on small planted modules --------------------------------------------------


def _check(code: str) -> list[str]:
    return sorted(what for _, what in unguarded(textwrap.dedent(code)))


@pytest.mark.parametrize(
    ("code", "expected"),
    [
        ("import fcntl\n", ["import fcntl"]),
        ("import os, termios\n", ["import termios"]),
        ("from resource import setrlimit\n", ["from resource import ..."]),
        ("def f():\n    import pwd\n    return pwd\n", ["import pwd"]),
        ("import msvcrt\n", ["import msvcrt"]),
        ("import os\nos.fork()\n", ["os.fork"]),
        ("import os\ndef f():\n    os.setsid()\n    os.killpg(1, 2)\n", ["os.killpg", "os.setsid"]),
        ("import os\nuid = os.getuid()\n", ["os.getuid"]),
        ("import os\nos.setpgid(0, 0)\nos.getpgid(0)\n", ["os.getpgid", "os.setpgid"]),
        ("from os import fork\n", ["from os import fork"]),
        ("import signal\nsignal.signal(signal.SIGHUP, print)\n", ["signal.SIGHUP"]),
        ("import signal\nsignal.alarm(1)\n", ["signal.alarm"]),
        ("from signal import SIGKILL\n", ["from signal import SIGKILL"]),
        ("import signal\nfor s in (signal.SIGUSR1, signal.SIGCHLD): pass\n", ["signal.SIGCHLD", "signal.SIGUSR1"]),
        # the case: OSError is what a refused call raises, not what a missing name raises
        (
            """
            import os
            def _normal():
                try:
                    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
                except OSError:
                    return False
                return True
            """,
            ["os.SCHED_OTHER", "os.sched_param", "os.sched_setscheduler"],
        ),
        # an import error is not caught by AttributeError, nor the other way round
        ("try:\n    import fcntl\nexcept AttributeError:\n    pass\n", ["import fcntl"]),
        ("import os\ntry:\n    os.fork()\nexcept ImportError:\n    pass\n", ["os.fork"]),
        # the handler and the else of a try are not guarded by it
        ("import os\ntry:\n    pass\nexcept AttributeError:\n    os.fork()\n", ["os.fork"]),
        ("import os\ntry:\n    pass\nexcept AttributeError:\n    pass\nelse:\n    os.fork()\n", ["os.fork"]),
        # a condition about something else is not a platform check
        ("import os\nif x:\n    os.fork()\n", ["os.fork"]),
        ("import os\nif x:\n    return_ = 1\nos.fork()\n", ["os.fork"]),
    ],
)
def test_the_checker_finds_a_planted_call(code, expected):
    assert _check(code) == expected


@pytest.mark.parametrize(
    "code",
    [
        "import sys\nif sys.platform != 'win32':\n    import fcntl\n",
        "import os\nif os.name == 'posix':\n    os.setsid()\nelse:\n    pass\n",
        "import os\nif hasattr(os, 'fork'):\n    os.fork()\n",
        "import platform, os\nif platform.system() == 'Linux':\n    os.nice(1)\n",
        "try:\n    import fcntl\nexcept ImportError:\n    fcntl = None\n",
        "try:\n    import termios\nexcept (OSError, ModuleNotFoundError):\n    pass\n",
        "import os\ntry:\n    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))\n"
        "except (AttributeError, OSError):\n    pass\n",
        "import os\ndef f():\n    if not hasattr(os, 'killpg'):\n        return None\n    os.killpg(1, 15)\n",
        "import os, sys\ndef f():\n    if sys.platform == 'win32':\n        raise RuntimeError\n"
        "    return os.getuid()\n",
        "import os\nsetter = getattr(os, 'sched_setscheduler', None)\n",
        "import os, sys\nx = os.getuid() if sys.platform != 'win32' else 0\n",
        "import signal\nsignal.signal(signal.SIGINT, print)\nsignal.signal(signal.SIGTERM, signal.SIG_DFL)\n",
        "import os\nos.kill(1, 15)\nos.getpid()\n",
    ],
)
def test_the_checker_accepts_a_guarded_call(code):
    assert _check(code) == []
