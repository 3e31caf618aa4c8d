"""``fgloc view``: the Foxglove view's helpers (the view itself: ``fgloc run/live --view``)."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    view = typer.Typer(help="Foxglove view: the layout for `fgloc run/live --view` and run.mcap.",
                       no_args_is_help=True)
    app.add_typer(view, name="view")

    @view.command("layout")
    def layout_cmd(
        out: Path | None = typer.Option(None, "-o", "--output", help="write the layout JSON here (default: stdout)"),
        force: bool = typer.Option(False, "--force", help="overwrite an existing file"),
    ) -> None:
        """The Foxglove layout for the view channels (Foxglove: Layouts -> Import from file)."""
        from fgloc.view.layout import layout_json

        text = layout_json()
        if out is None:
            print(text, end="")
            return
        from fgloc.io.outputs import write_text_output

        write_text_output(out, text, force=force, what="layout", command="view layout")
        print(f"wrote {out} (Foxglove: Layouts -> Import from file)")
