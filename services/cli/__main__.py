"""`python -m prism_cli` runs the `prism` command."""

from .main import app

app()
