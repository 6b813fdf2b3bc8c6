import sys

from vibsynth.cli import main

sys.exit(main())
