"""CLI subcommand modules; each exposes ``register(app: typer.Typer)``."""
