import sys

from tdmon.cli import main

sys.exit(main())
