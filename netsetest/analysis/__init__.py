"""Offline analyses of run records (the exact tightest bounds, comparisons); nothing here imports the CLI."""
