"""``python -m tdmon``: importing tdmon.cli first arms SIGINT (see its docstring)."""

import tdmon.cli

raise SystemExit(tdmon.cli.main())
