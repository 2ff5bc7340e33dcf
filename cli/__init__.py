"""The ``colossus`` command line (the top floor): a thin click layer over the library.

One module per command, loaded lazily so ``colossus --help`` stays fast and a missing optional
extra breaks only the commands that need it; the error mapping every command shares is
:mod:`colossus.cli._errors`:

=========== =============================== ======================================
command     module                          what
=========== =============================== ======================================
import      ``colossus.cli.import_``        an export in, a USD collider out
validate    ``colossus.cli.validate``       CI asset checks
build       ``colossus.cli.build``          the project file's assets, rebuilt when changed
check       ``colossus.cli.build``          CI gate over the project file's assets
config      ``colossus.cli.build``          the project file's resolved settings
inspect     ``colossus.cli.inspect``        human summary of an asset
render      ``colossus.cli.render``         picture of the collider and its spheres
play        ``colossus.cli.play``           player sphere demo on an animated collider
bench       ``colossus.cli.bench``          benchmarks (ratios against in-process baselines)
=========== =============================== ======================================
"""

from __future__ import annotations

import importlib

import click

from colossus._version import __version__

from ._errors import CommandError, maps_errors, missing_extra, on_sigterm  # noqa: F401  (the commands' shared error mapping)

#: name -> (module, attribute, one-line help shown by ``colossus --help``)
COMMANDS = {
    "import": ("colossus.cli.import_", "import_cmd", "Import a Blender export and write a USD collider asset."),
    "validate": ("colossus.cli.validate", "validate_cmd", "Check collider assets (CI gate)."),
    "build": ("colossus.cli.build", "build_cmd", "Import the project file's assets whose inputs changed."),
    "check": ("colossus.cli.build", "check_cmd", "CI gate: every project asset built, up to date and passing."),
    "config": ("colossus.cli.build", "config_cmd", "Print the project file's resolved settings per asset."),
    "inspect": ("colossus.cli.inspect", "inspect_cmd", "Print a readable summary of a collider asset."),
    "render": ("colossus.cli.render", "render_cmd", "Render the collider and its part spheres to PNG or GIF."),
    "play": ("colossus.cli.play", "play_cmd", "Drop a player sphere on an animated collider and record it."),
    "bench": ("colossus.cli.bench", "bench_cmd", "Run the benchmarks and print ratios against baselines."),
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
        try:
            return getattr(importlib.import_module(mod), attr)
        except ModuleNotFoundError as e:  # an optional extra missing: the command says which
            err = missing_extra(e, name)
            if err is None:
                raise

            @click.command(name, context_settings={"ignore_unknown_options": True, "allow_extra_args": True},
                           add_help_option=False)
            def unavailable():
                raise err

            return unavailable

    def format_commands(self, ctx, formatter):
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version=__version__, prog_name="colossus")
def main():
    """colossus: deformable mesh colliders from rigged, animated Blender exports.

    \b
    colossus import creature.glb -o creature.usda     # build a collider asset
    colossus validate creature.usda                   # prove it holds on every frame
    """
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        # SIGTERM (a CI job's timeout) is handled like Ctrl-C: what finished is reported, exit 143
        signal.signal(signal.SIGTERM, on_sigterm)
    from colossus.runtime import usdlog

    usdlog.silence()  # usd-core's own warnings never reach the terminal: one line per problem, ours


if __name__ == "__main__":  # pragma: no cover
    main()
