"""``python -m vtkraycast``: the command line."""

from .cli import main

raise SystemExit(main())
