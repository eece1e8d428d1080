"""`python -m relocation_app.evaluation.scenes KIND ...`: the scene maker (scenes/cli.py)."""
from relocation_app.evaluation.scenes.cli import main

raise SystemExit(main())
