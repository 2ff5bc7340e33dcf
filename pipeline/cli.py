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
bench       ``validators.cli_bench``        benchmarks (ratios against in-process baselines)
=========== =============================== ======================================
"""

from __future__ import annotations

import functools
import importlib
import os

import click

from runtime.errors import ColossusError, one_line

#: name -> (module, attribute, one-line help shown by ``colossus --help``)
COMMANDS = {
    "import": ("pipeline.cli_import", "import_cmd", "Import a Blender export and write a USD collider asset."),
    "validate": ("validators.cli", "validate_cmd", "Check collider assets (CI gate)."),
    "inspect": ("validators.cli_inspect", "inspect_cmd", "Print a readable summary of a collider asset."),
    "render": ("validators.cli_render", "render_cmd", "Render the collider and its part spheres to PNG or GIF."),
    "play": ("runtime.cli", "play_cmd", "Drop a player sphere on an animated collider and record it."),
    "bench": ("validators.cli_bench", "bench_cmd", "Run the benchmarks and print ratios against baselines."),
}


class CommandError(click.ClickException):
    """One of our errors on the command line: one line on stderr, ``error: <message>``, and an
    exit status (click's standalone mode prints it and exits)."""

    def __init__(self, message: str, exit_code: int = 1):
        super().__init__(message)
        self.exit_code = exit_code

    def show(self, file=None):
        click.echo(f"error: {self.format_message()}", err=True)


def maps_errors(input_status: int = 1):
    """Decorate a command so the project's errors become exit statuses, the same way for every
    command (click's ``ClickException``/``UsageError`` pattern):

    * :class:`pipeline.errors.UsageError` -> 2 (usage);
    * any other :class:`~runtime.errors.ColossusError` (an unusable input, an unreadable asset,
      an unwritable output) -> ``input_status`` (1 for ``import``; 2 for ``inspect``/``render``,
      whose contract says an unreadable asset is status 2);
    * ``MemoryError`` -> 1 "out of memory"; Ctrl-C -> 130 "interrupted";
    * anything else -> 1 "internal error (...)" with no traceback (``COLOSSUS_DEBUG=1`` shows it).

    click's own exits and usage errors pass through untouched.
    """
    from pipeline.errors import UsageError

    def wrap(fn):
        @functools.wraps(fn)
        def run(*args, **kwargs):
            try:
                return fn(*args, **kwargs)
            except (click.exceptions.Exit, click.ClickException, click.Abort):
                raise
            except UsageError as e:
                raise CommandError(one_line(e), 2) from None
            except ColossusError as e:
                raise CommandError(one_line(e, limit=600), input_status) from None
            except MemoryError:
                raise CommandError("out of memory", 1) from None
            except KeyboardInterrupt:
                raise CommandError("interrupted", 130) from None
            except Exception as e:  # never a traceback on user input
                if os.environ.get("COLOSSUS_DEBUG"):
                    raise
                raise CommandError(f"internal error ({type(e).__name__}: {one_line(e)}); rerun with "
                                   "COLOSSUS_DEBUG=1 for details", 1) from None
        return run
    return wrap


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
