"""`python -m vehid_cli` runs the command line."""

from .cli import run

run()
