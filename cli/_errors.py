"""How the command line reports our errors: one line on stderr and an exit status, the same way
for every command (click's ``ClickException`` / ``UsageError`` pattern)."""

from __future__ import annotations

import functools
import os

import click

from colossus.runtime.errors import ColossusError, one_line

#: Third-party module -> the optional extra that installs it (``pyproject.toml``).  A runtime-only
#: install has none of them; a command that needs one says which extra to install.
EXTRA_OF = {"assimp_py": "pipeline", "scipy": "pipeline", "trimesh": "pipeline", "meshio": "pipeline",
            "fast_simplification": "pipeline", "pyvista": "render", "vtk": "render", "vtkmodules": "render",
            "matplotlib": "render", "PIL": "render", "imageio": "render", "dask": "dask",
            "distributed": "dask", "embreex": "bench", "rtree": "bench"}


#: (command, module) -> a smaller extra that brings the module for that command
EXTRA_FOR_COMMAND = {("validate", "scipy"): "validate", ("inspect", "scipy"): "validate"}


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled like Ctrl-C (what finished is reported) but with its own status, 143."""


def on_sigterm(signum, frame):  # installed by the command group for every command
    note_terminated()
    raise Terminated()


def interrupted_status(exc: BaseException | None = None) -> int:
    """130 for Ctrl-C, 143 for SIGTERM (128 + the signal number, as a shell reports them)."""
    return 143 if isinstance(exc, Terminated) or _TERMINATED[0] else 130


_TERMINATED = [False]


def note_terminated() -> None:
    _TERMINATED[0] = True


def missing_extra(e: ModuleNotFoundError, command: str | None = None) -> CommandError | None:
    """The one-line error (exit 2: this install cannot run it) for a command that needs an optional
    extra that is not installed; None when ``e`` is not about one."""
    name = (e.name or "").split(".")[0]
    extra = EXTRA_FOR_COMMAND.get((command, name), EXTRA_OF.get(name))
    if extra is None:
        return None
    what = f"colossus {command}" if command else "this command"
    return CommandError(f"{what} needs {name}, which is not installed (the {extra!r} extra): "
                        f"pip install 'colossus-colliders[{extra}]'", 2)


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

    * :class:`pipeline.errors.UsageError` -> 2 (usage), and
      :class:`pipeline.errors.OutputError` -> 2 (the environment: an output folder missing,
      read-only or full; never "the input is unusable");
    * any other :class:`~runtime.errors.ColossusError` (an unusable input, an unreadable asset,
      an unwritable output) -> ``input_status`` (1 for ``import``; 2 for ``inspect``/``render``,
      whose contract says an unreadable asset is status 2);
    * a missing optional extra (:data:`EXTRA_OF`) -> 2, naming the extra to install;
    * ``MemoryError`` -> 1 "out of memory"; Ctrl-C -> 130 "interrupted"; SIGTERM -> 143
      "terminated" (:func:`on_sigterm`);
    * anything else -> 1 "internal error (...)" with no traceback (``COLOSSUS_DEBUG=1`` shows it).

    click's own exits and usage errors pass through untouched.
    """
    from colossus.pipeline.errors import OutputError, UsageError

    def wrap(fn):
        @functools.wraps(fn)
        def run(*args, **kwargs):
            try:
                return fn(*args, **kwargs)
            except (click.exceptions.Exit, click.ClickException, click.Abort):
                raise
            except (UsageError, OutputError) as e:  # a bad option, or an output that cannot be written
                raise CommandError(one_line(e), 2) from None
            except ColossusError as e:
                raise CommandError(one_line(e, limit=600), input_status) from None
            except MemoryError:
                raise CommandError("out of memory", 1) from None
            except KeyboardInterrupt as e:
                status = interrupted_status(e)
                raise CommandError("terminated" if status == 143 else "interrupted", status) from None
            except Exception as e:  # never a traceback on user input
                if isinstance(e, ModuleNotFoundError):  # an optional extra this install lacks
                    ctx = click.get_current_context(silent=True)
                    err = missing_extra(e, ctx.info_name if ctx else None)
                    if err is not None:
                        raise err from None
                if os.environ.get("COLOSSUS_DEBUG"):
                    raise
                raise CommandError(f"internal error ({type(e).__name__}: {one_line(e)}); rerun with "
                                   "COLOSSUS_DEBUG=1 for details", 1) from None
        return run
    return wrap
