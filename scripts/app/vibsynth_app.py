"""The PyInstaller app's entry point: the ``vibsynth`` command (scripts/vibsynth-app.spec)."""

import multiprocessing
import sys

from vibsynth.cli import main

if __name__ == "__main__":
    multiprocessing.freeze_support()  # a frozen child process (Windows, macOS spawn) runs its task, not the CLI
    sys.exit(main())
