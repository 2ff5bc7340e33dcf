"""The ``colossus`` command line: a thin click layer over the library.

Subcommands live next to the code they drive and are loaded lazily, so ``colossus --help``
stays fast and one package's import error cannot break another's command:

=========== =============================== ======================================
command     module                          what
=========== =============================== ======================================
import      ``pipeline.cli_import``         Blender export in, USD collider out
validate    ``validators.cli``              CI asset checks
inspect     ``validators.cli_inspect``      human summary of an asset
render      ``validators.cli_render``       picture of the collider and its spheres
play        ``runtime.cli``                 player sphere demo on an animated collider
bench       ``pipeline.bench``              benchmarks (ratios against in-process baselines)
=========== =============================== ======================================
"""

from __future__ import annotations

import importlib

import click

#: name -> (module, attribute, one-line help shown by ``colossus --help``)
COMMANDS = {
    "import": ("pipeline.cli_import", "import_cmd", "Import a Blender export and write a USD collider asset."),
    "validate": ("validators.cli", "validate_cmd", "Check collider assets (CI gate)."),
    "inspect": ("validators.cli_inspect", "inspect_cmd", "Print a readable summary of a collider asset."),
    "render": ("validators.cli_render", "render_cmd", "Render the collider and its part spheres to PNG or GIF."),
    "play": ("runtime.cli", "play_cmd", "Drop a player sphere on an animated collider and record it."),
    "bench": ("pipeline.bench", "bench_cmd", "Run the benchmarks and print ratios against baselines."),
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx):
        return [name for name in COMMANDS if self._available(name)]

    def _available(self, name):
        mod = COMMANDS[name][0]
        try:
            return importlib.util.find_spec(mod) is not None
        except ModuleNotFoundError:
            return False

    def get_command(self, ctx, name):
        if name not in COMMANDS or not self._available(name):
            return None
        mod, attr, _ = COMMANDS[name]
        return getattr(importlib.import_module(mod), attr)

    def format_commands(self, ctx, formatter):
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="colossus", prog_name="colossus")
def main():
    """colossus: deformable mesh colliders from rigged, animated Blender exports.

    \b
    colossus import creature.glb -o creature.usda     # build a collider asset
    colossus validate creature.usda                   # prove it holds on every frame
    """


if __name__ == "__main__":  # pragma: no cover
    main()
