"""``fgloc config show`` / ``fgloc config init``: the one configuration, documented."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    cfg_app = typer.Typer(help="The configuration: show the effective one, write a starting file.",
                          no_args_is_help=True)
    app.add_typer(cfg_app, name="config")

    @cfg_app.command("show")
    def show(
        config: Path | None = typer.Option(None, "--config", help="YAML overlaid on the defaults (checked)"),
        plain: bool = typer.Option(False, "--plain", help="no comments"),
    ) -> None:
        """Print the effective configuration as YAML: every key, its value and what it does."""
        from fgloc.config import config_yaml, load_config

        cfg = load_config(config)
        header = None if config is None else f"effective configuration: the defaults overlaid with {config}"
        print(config_yaml(cfg, comments=not plain, **({} if header is None else {"header": header})), end="")

    @cfg_app.command("init")
    def init(
        output: Path = typer.Option(..., "-o", "--output", help="the YAML file to write"),
        force: bool = typer.Option(False, "--force", help="overwrite an existing file"),
    ) -> None:
        """Write a commented starting config (every key with its default)."""
        from fgloc.config import config_yaml
        from fgloc.io.outputs import write_text_output

        write_text_output(output, config_yaml(), force=force, what="config", command="config")
        print(f"wrote {output}")
