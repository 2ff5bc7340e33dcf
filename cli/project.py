"""The project file (issue 23): ``colossus.toml``, or ``[tool.colossus]`` in ``pyproject.toml``,
found by walking up from the working directory like ruff (or named with ``--config FILE``).

::

    [import]                       # defaults for every entry: any `colossus import` option
    up-axis = "Y"
    max-influences = 4

    [validate]                     # the rules `colossus check` (and plain `colossus validate`) run
    select = ["COL"]
    ignore = ["COL206"]
    severity = { COL404 = "error" }
    subframes = 0
    max-deviation = "1%"
    strict = false                 # warnings fail too

    [[asset]]
    source = "exports/*.glb"       # a path or a glob, relative to the project file's folder
    output = "colliders/{stem}.usdc"   # {stem} {name} {ext} {dir}
    max-influences = 2             # any [import] key, for this entry
    ignore = ["COL404"]            # a per-entry waiver ...
    reason = "cloth proxy, slack by design"   # ... only with a reason

Everything wrong in the file (an unknown key, a wrong type, a glob that matches nothing, a waiver
without a reason, two entries writing one output) is a :class:`ProjectError` naming the file,
the line and the key: exit 2 on the command line.

A build key (:func:`build_stamp`) is the sha256 of the source's bytes and of every file it pulls
in (:func:`dependencies`: glTF ``.bin`` buffers, USD sublayers, references, payloads and value
clips, followed recursively), of the resolved import settings, and of the importer's version.
``colossus build`` stores it in the asset's provenance (``customData["colossus"]["build"]``) and
``colossus check`` reads it back (:func:`read_stamp`).
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import re
import tomllib
from dataclasses import asdict, dataclass, field

from colossus.pipeline.errors import UsageError

PROJECT_FILE = "colossus.toml"
PYPROJECT = "pyproject.toml"
#: Bumped when what goes into a build key changes (every entry then rebuilds once).
KEY_SCHEME = 1


class ProjectError(UsageError):
    """A bad project file: the message names the file, the line and the key (exit 2)."""


#: ``[import]`` / per-entry key -> (ImportSettings field, accepted Python types, what the error says)
IMPORT_KEYS = {
    "up-axis": ("up_axis", (str,), "a string, Y or Z"),
    "meters-per-unit": ("meters_per_unit", (int, float), "a number"),
    "max-influences": ("max_influences", (int,), "an integer"),
    "unweighted": ("unweighted", (str,), "a string (error or nearest-bone)"),
    "parts": ("parts", (str,), "a string (dominant or any)"),
    "parts-threshold": ("parts_threshold", (int, float), "a number"),
    "min-part-faces": ("min_part_faces", (int,), "an integer"),
    "mesh": ("meshes", (list,), "a list of mesh names"),
    "fps": ("fps", (int, float), "a number"),
    "source-up-axis": ("source_up_axis", (str,), "a string, Y or Z"),
    "source-meters-per-unit": ("source_meters_per_unit", (int, float), "a number"),
    "target-faces": ("target_faces", (int,), "an integer"),
    "max-deviation": ("max_deviation", (str, int, float), "a length or a percentage such as \"1%\""),
    "allow-outside-references": ("allow_outside_references", (bool,), "true or false"),
    "strict": ("strict", (bool,), "true or false"),
}
#: ``[validate]`` key -> (accepted types, what the error says)
VALIDATE_KEYS = {
    "select": ((list,), "a list of rule codes or prefixes"),
    "ignore": ((list,), "a list of rule codes or prefixes"),
    "severity": ((dict,), "a table of CODE = \"error\" | \"warning\" | \"info\""),
    "subframes": ((int,), "an integer >= 0"),
    "max-deviation": ((str, int, float), "a length or a percentage such as \"1%\""),
    "max-influences": ((int,), "an integer"),
    "slack-ratio": ((int, float), "a number >= 1"),
    "strict": ((bool,), "true or false"),
}
ENTRY_KEYS = {"source": ((str,), "a path or a glob"), "output": ((str,), "a pattern such as \"colliders/{stem}.usdc\""),
              "name": ((str,), "a string"), "ignore": ((list,), "a list of rule codes or prefixes"),
              "reason": ((str,), "a non-empty string")}
OUTPUT_FIELDS = ("stem", "name", "ext", "dir")


@dataclass
class Entry:
    """One source of one ``[[asset]]`` entry, resolved (a glob entry gives one per file)."""

    index: int                 #: the entry's position among the ``[[asset]]`` tables (0-based)
    name: str                  #: the entry's ``name``, else its ``source`` as written
    source: str                #: absolute path
    output: str                #: absolute path
    settings: object           #: pipeline.run.ImportSettings
    strict: bool = False       #: import --strict
    validate: dict = field(default_factory=dict)   #: check_many keyword arguments
    validate_strict: bool = False
    waiver: dict | None = None  #: {"ignore": [...], "reason": "..."}


@dataclass
class Project:
    path: str                  #: the project file
    root: str                  #: its folder: paths in the file are relative to it
    table: dict                #: the colossus table as read
    entries: list
    validate: dict             #: [validate] as check_many keyword arguments
    validate_strict: bool = False


# ------------------------------------------------------------------------------ finding the file
def find_project(start: str | None = None) -> str | None:
    """The project file governing ``start`` (default the working directory): walking up, the first
    folder with a ``colossus.toml``, or a ``pyproject.toml`` holding ``[tool.colossus]`` (one
    without that table is passed over, as ruff does); None when there is none."""
    d = os.path.abspath(start or os.getcwd())
    while True:
        cand = os.path.join(d, PROJECT_FILE)
        if os.path.isfile(cand):
            return cand
        cand = os.path.join(d, PYPROJECT)
        if os.path.isfile(cand):
            try:
                with open(cand, "rb") as fh:
                    if "colossus" in (tomllib.load(fh).get("tool") or {}):
                        return cand
            except (OSError, tomllib.TOMLDecodeError):
                pass
        parent = os.path.dirname(d)
        if parent == d:
            return None
        d = parent


# ------------------------------------------------------------------------------ line numbers
def key_line(text: str, table: str | None, key: str | None, entry: int | None = None, prefix: str = "") -> int:
    """The 1-based line of ``key`` in ``[table]`` (or in the ``entry``-th ``[[table]]``) of the TOML
    ``text``; the table's header line when the key is not found; 1 when neither is.

    ``tomllib`` gives no line numbers, so this is a plain scan of the text: it follows ``[x]`` /
    ``[[x]]`` headers (``prefix``, e.g. ``tool.colossus.``, stripped) and matches ``key =`` at the
    start of a line, or ``key`` inside an inline table of that section.  Good enough to point a
    person at the right line; it is not a TOML parser (a key inside a multi-line string could fool it).
    """
    current, count, header_line, found = None, -1, None, None
    head = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
    for no, line in enumerate(text.splitlines(), 1):
        m = head.match(line)
        if m:
            name = m.group(2).replace('"', "").replace(" ", "")
            if prefix and name == prefix.rstrip("."):
                name = ""  # [tool.colossus] itself: its top level
            elif prefix and name.startswith(prefix):
                name = name[len(prefix):]
            elif prefix:
                name = None  # another tool's table
            current = name
            if name == table and m.group(1) == "[[":
                count += 1
            if name == table and (entry is None or count == entry) and header_line is None:
                header_line = no
            continue
        top = "" if prefix else None  # the section the file's own top-level keys sit in
        in_section = (current == top) if table is None else (current == table and (entry is None or count == entry))
        if in_section and key is not None:
            if re.match(rf'^\s*"?{re.escape(key)}"?\s*=', line) or re.search(rf'[{{,]\s*"?{re.escape(key)}"?\s*=', line):
                found = no
                break
    return found or header_line or 1


# ------------------------------------------------------------------------------ loading
def parse_overrides(items) -> dict:
    """``--set KEY=VALUE`` options (VALUE in TOML: ``max-influences=2``, ``mesh=["Body"]``,
    ``up-axis=Z``, bare words taken as strings) as ``{"import": {...}, "validate": {...}}``; a key
    ``validate.NAME`` goes to ``[validate]``, any other to ``[import]``.  Raises :class:`UsageError`."""
    out = {"import": {}, "validate": {}}
    for item in items or ():
        key, eq, value = str(item).partition("=")
        key = key.strip()
        if not eq or not key:
            raise UsageError(f"--set {item!r}: expected KEY=VALUE, e.g. max-influences=2")
        try:
            v = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            v = value.strip()
        table, _, name = key.rpartition(".")
        table = table or "import"
        if table not in out:
            raise UsageError(f"--set {item!r}: a key is NAME (an [import] option) or validate.NAME")
        out[table][name] = v
    return out


def load_project(path: str | None = None, start: str | None = None, overrides: dict | None = None) -> Project:
    """Read and check the project file ``path`` (default: :func:`find_project` from ``start``);
    raises :class:`ProjectError` when there is none or it is wrong.  ``overrides``
    (:func:`parse_overrides`: the command line's ``--set``) win over the file, per-asset values
    included."""
    from colossus.pipeline.run import ImportSettings

    if path is None:
        path = find_project(start)
        if path is None:
            raise ProjectError(f"no project file: no {PROJECT_FILE}, nor a {PYPROJECT} with [tool.colossus], "
                               f"in {os.path.abspath(start or os.getcwd())} or any folder above it")
    path = os.path.abspath(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as e:
        raise ProjectError(f"{path}: cannot read the project file: {e.strerror or e}") from None
    text = raw.decode("utf-8", errors="replace")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ProjectError(f"{path}: not valid TOML: {e}") from None
    prefix = ""
    if os.path.basename(path) == PYPROJECT:
        doc = (doc.get("tool") or {}).get("colossus")
        prefix = "tool.colossus."
        if doc is None:
            raise ProjectError(f"{path}: has no [tool.colossus] table")
    root = os.path.dirname(path)

    def err(table, key, msg, entry=None):
        line = key_line(text, table, key, entry, prefix)
        where = f"{prefix}{table}" if table else (prefix.rstrip(".") or "top level")
        if entry is not None:
            where += f"[{entry}]"
        what = f"{where}.{key}" if key else where
        return ProjectError(f"{path}:{line}: {what}: {msg}")

    def check_type(table, key, value, types, what, entry=None):
        if isinstance(value, bool) and bool not in types:
            raise err(table, key, f"expected {what}, got {value!r}", entry)
        if not isinstance(value, types):
            raise err(table, key, f"expected {what}, got {type(value).__name__} {value!r}", entry)

    for k, v in doc.items():
        if k not in ("import", "validate", "asset"):
            raise err(None, k, "unknown key (expected [import], [validate] or [[asset]])")
    imp = doc.get("import", {})
    if not isinstance(imp, dict):
        raise err(None, "import", "expected a table [import]")
    base_import = _import_options(imp, "import", None, err, check_type)
    over = overrides or {}

    def flag_err(table, key, msg, entry=None):
        return ProjectError(f"--set {'validate.' if table == 'validate' else ''}{key}: {msg}")

    cli_import = _import_options(over.get("import") or {}, "import", None, flag_err, _type_checker(flag_err))
    val = doc.get("validate", {})
    if not isinstance(val, dict):
        raise err(None, "validate", "expected a table [validate]")
    validate, vstrict = _validate_options(val, err, check_type)
    if over.get("validate"):
        extra, s2 = _validate_options(over["validate"], flag_err, _type_checker(flag_err))
        validate.update(extra)
        vstrict = s2 if "strict" in over["validate"] else vstrict
    assets = doc.get("asset", [])
    if not isinstance(assets, list) or not all(isinstance(a, dict) for a in assets):
        raise err(None, "asset", "expected [[asset]] tables")
    entries, outputs = [], {}
    for i, a in enumerate(assets):
        for k, v in a.items():
            if k in ENTRY_KEYS:
                check_type("asset", k, v, ENTRY_KEYS[k][0], ENTRY_KEYS[k][1], i)
            elif k not in IMPORT_KEYS:
                raise err("asset", k, "unknown key (expected source, output, name, ignore, reason, or an "
                                      "[import] option such as max-influences)", i)
        for req in ("source", "output"):
            if req not in a:
                raise err("asset", None, f"the entry has no {req!r}", i)
        opts = {**base_import, **_import_options({k: v for k, v in a.items() if k in IMPORT_KEYS}, "asset", i,
                                                 err, check_type), **cli_import}
        strict = bool(opts.pop("strict", False))
        try:
            settings = ImportSettings(**opts)
            settings.check()
        except UsageError as e:  # a value out of range: name the key where it was set
            m = re.search(r"--([a-z-]+)", str(e))
            key = m.group(1) if m and m.group(1) in IMPORT_KEYS else None
            msg = str(e)
            if key is not None and key in (over.get("import") or {}):
                raise flag_err("import", key, msg) from None
            if key is not None and key not in a and key in imp:
                raise err("import", key, msg) from None
            raise err("asset", key if key in a else None, msg, i) from None
        waiver = None
        if "ignore" in a:
            reason = str(a.get("reason", "")).strip()
            if not reason:
                raise err("asset", "ignore", "a per-asset ignore needs a reason (reason = \"why this waiver\")", i)
            codes = _codes(a["ignore"], "asset", "ignore", err, i)
            waiver = {"ignore": codes, "reason": reason}
        elif "reason" in a:
            raise err("asset", "reason", "a reason without an ignore waives nothing", i)
        pattern = a["output"]
        if not pattern.lower().endswith((".usda", ".usdc", ".usd")):
            raise err("asset", "output", f"{pattern!r}: an output ends in .usda, .usdc or .usd", i)
        try:
            pattern.format(**{k: "x" for k in OUTPUT_FIELDS})
        except (KeyError, IndexError, ValueError) as e:
            raise err("asset", "output", f"{pattern!r}: unknown field {e} (fields: "
                                         + ", ".join("{" + f + "}" for f in OUTPUT_FIELDS) + ")", i) from None
        sources = _expand(root, a["source"])
        if not sources:
            what = "matches no file" if glob.has_magic(a["source"]) else "no such file"
            raise err("asset", "source", f"{a['source']!r}: {what} (relative to {root})", i)
        v = dict(validate)
        if waiver:
            v["ignore"] = list(v.get("ignore") or []) + waiver["ignore"]
        for src in sources:
            out = os.path.normpath(os.path.join(root, pattern.format(**_fields(root, src))))
            if out in outputs:
                j, other = outputs[out]
                raise err("asset", "output", f"{src} and {other} (entry {j}) would both write {out}", i)
            outputs[out] = (i, src)
            entries.append(Entry(i, a.get("name", a["source"]), src, out, settings, strict, v, vstrict, waiver))
    return Project(path, root, doc, entries, validate, vstrict)


def _type_checker(err):
    def check_type(table, key, value, types, what, entry=None):
        if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
            raise err(table, key, f"expected {what}, got {value!r}", entry)
    return check_type


def _import_options(table, where, entry, err, check_type) -> dict:
    out = {}
    for k, v in table.items():
        if k not in IMPORT_KEYS:
            raise err(where, k, "unknown key (import options: " + ", ".join(IMPORT_KEYS) + ")", entry)
        fld, types, what = IMPORT_KEYS[k]
        check_type(where, k, v, types, what, entry)
        if k == "mesh" and not all(isinstance(m, str) for m in v):
            raise err(where, k, f"expected {what}", entry)
        if k in ("up-axis", "source-up-axis"):
            v = v.upper()
        if isinstance(v, int) and not isinstance(v, bool) and float in types and int in types and k != "max-deviation":
            v = float(v)
        if k == "max-deviation":
            v = str(v)
        out[fld] = v
    return out


def _codes(values, table, key, err, entry=None) -> list:
    from colossus.validators.registry import RuleSelector

    if not all(isinstance(c, str) for c in values):
        raise err(table, key, "expected a list of rule codes or prefixes (strings)", entry)
    codes = [c.strip().upper() for c in values if c.strip()]
    try:
        RuleSelector(codes)
    except ValueError as e:
        raise err(table, key, str(e), entry) from None
    return codes


def _validate_options(table, err, check_type):
    out = {}
    strict = False
    for k, v in table.items():
        if k not in VALIDATE_KEYS:
            raise err("validate", k, "unknown key (validate options: " + ", ".join(VALIDATE_KEYS) + ")")
        types, what = VALIDATE_KEYS[k]
        check_type("validate", k, v, types, what)
        if k in ("select", "ignore"):
            out[k] = _codes(v, "validate", k, err)
        elif k == "severity":
            from colossus.validators.registry import get_rule
            sev = {}
            for code, level in v.items():
                if level not in ("error", "warning", "info"):
                    raise err("validate", code, f"severity {level!r}: expected error, warning or info")
                try:
                    get_rule(code.upper())
                except KeyError:
                    raise err("validate", code, f"unknown rule code {code!r}") from None
                sev[code.upper()] = level
            out["severities"] = sev
        elif k == "subframes":
            if v < 0:
                raise err("validate", k, f"expected an integer >= 0, got {v}")
            out["subframes"] = v
        elif k == "max-deviation":
            from colossus.pipeline.options import parse_max_deviation
            try:
                parse_max_deviation(str(v))
            except UsageError as e:
                raise err("validate", k, str(e)) from None
            out["max_deviation"] = str(v)
        elif k == "max-influences":
            out["max_influences"] = v
        elif k == "slack-ratio":
            if v < 1:
                raise err("validate", k, f"expected a number >= 1, got {v}")
            out["slack_ratio"] = float(v)
        elif k == "strict":
            strict = v
    return out, strict


def _expand(root: str, pattern: str) -> list:
    full = os.path.join(root, os.path.expanduser(pattern))
    if glob.has_magic(pattern):
        return sorted(os.path.normpath(p) for p in glob.glob(full, recursive=True) if os.path.isfile(p))
    return [os.path.normpath(full)] if os.path.isfile(full) else []


def _fields(root: str, src: str) -> dict:
    base = os.path.basename(src)
    stem, ext = os.path.splitext(base)
    d = os.path.relpath(os.path.dirname(src), root)
    return {"stem": stem, "name": base, "ext": ext.lstrip("."), "dir": "" if d == "." else d}


def select_entries(project: Project, names) -> list:
    """The entries ``colossus build NAME...`` means: each name is an entry's ``name``, its
    ``source`` as written, a source file, or an output file; unknown names are a usage error."""
    if not names:
        return list(project.entries)
    picked, seen = [], set()
    for n in names:
        full = os.path.normpath(os.path.abspath(n))
        hits = [e for e in project.entries
                if n == e.name or full in (e.source, e.output)
                or os.path.normpath(os.path.join(project.root, n)) in (e.source, e.output)]
        if not hits:
            raise UsageError(f"{n!r} is not an [[asset]] of {project.path} (give an entry's name, source or output)")
        for e in hits:
            if id(e) not in seen:
                seen.add(id(e))
                picked.append(e)
    return picked


# ------------------------------------------------------------------------------ build keys
def dependencies(src: str, allow_outside: bool = False) -> list:
    """The files ``src`` pulls in, in a stable order, followed recursively: a glTF's external
    buffers (``buffers[].uri``, as :mod:`pipeline.readers.gltf_reader` reads them) and a USD
    layer's sublayers, references, payloads and value clips
    (:func:`runtime.references.layer_references`), and an Ogre mesh's skeleton (the file its
    skeleton link names, as :mod:`pipeline.readers.ogre` reads it).  A reference that cannot be
    resolved is listed as ``missing:<ref>``, so the key changes when the file appears.  Other
    formats: none."""
    from colossus.runtime.references import OutsideReference, resolve

    out, seen = [], {os.path.realpath(src)}
    todo = [src]
    while todo:
        f = todo.pop(0)
        refs = []
        low = f.lower()
        if low.endswith((".gltf", ".glb")):
            refs = [(r, "buffer") for r in _gltf_buffer_uris(f)]
        elif low.endswith((".mesh", ".mesh.xml")):
            refs = [(r, "skeleton") for r in _ogre_skeleton_names(f)]
        elif low.endswith((".usd", ".usda", ".usdc")):
            try:
                from colossus.runtime.references import layer_references
                refs = [(r, "reference") for r in layer_references(f, composition_only=True)]
            except Exception:
                refs = []
        for r, what in refs:
            try:
                p = resolve(f, r, what, allow_outside=allow_outside)
            except OutsideReference:
                out.append(f"missing:{r}")
                continue
            k = os.path.realpath(p)
            if k in seen:
                continue
            seen.add(k)
            out.append(p)
            todo.append(p)
    return out


def _ogre_skeleton_names(path: str) -> list:
    """The skeleton files an Ogre mesh may read: each link, and for an XML mesh ``<link>.xml``
    first (the names :func:`pipeline.readers.ogre.check_skeleton` checks); those present, else the
    first name (missing: the key changes when it appears)."""
    from colossus.pipeline.readers import ogre

    try:
        links = ogre.skeleton_links(path)
    except Exception:
        return []  # an unreadable source: the import says why
    folder = os.path.dirname(os.path.abspath(path))
    out = []
    for link in links:
        names = [link + ".xml", link] if path.lower().endswith(".xml") and link.lower().endswith(".skeleton") else [link]
        present = [n for n in names if os.path.lexists(os.path.join(folder, n))]
        out += present or names[:1]
    return out


def _gltf_buffer_uris(path: str) -> list:
    import struct

    try:
        with open(path, "rb") as fh:
            data = fh.read()
        if data[:4] == b"glTF":
            clen, ctype = struct.unpack_from("<II", data, 12)
            data = data[20:20 + clen] if ctype == 0x4E4F534A else b"{}"
        j = json.loads(data.decode("utf-8-sig"))
        return [b["uri"] for b in j.get("buffers") or [] if isinstance(b, dict) and isinstance(b.get("uri"), str)
                and not b["uri"].startswith("data:")]
    except Exception:
        return []  # an unreadable source: the import says why


def _sha256_file(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def settings_digest(entry: Entry) -> str:
    s = asdict(entry.settings)
    s["strict"] = entry.strict
    return hashlib.sha256(json.dumps(s, sort_keys=True, default=str).encode()).hexdigest()


def inputs_digest(entry: Entry) -> tuple:
    """(sha256 over the source's and its dependencies' bytes, the source's own sha256, the files)."""
    h = hashlib.sha256()
    own = _sha256_file(entry.source)
    h.update(b"source\0" + own.encode())
    deps = dependencies(entry.source, entry.settings.allow_outside_references)
    for d in deps:
        rel = d if d.startswith("missing:") else os.path.relpath(d, os.path.dirname(entry.source))
        h.update(b"\0dep\0" + rel.encode() + b"\0")
        if not d.startswith("missing:"):
            h.update(_sha256_file(d).encode())
    return h.hexdigest(), own, deps


def importer_version() -> str:
    from colossus._version import __version__
    return f"colossus {__version__}"


def build_stamp(entry: Entry, importer: str | None = None) -> dict:
    """What ``colossus build`` stores in the asset (``customData["colossus"]["build"]``): the key
    and its three parts, so ``check`` can say which changed."""
    inputs, own, deps = inputs_digest(entry)
    settings = settings_digest(entry)
    importer = importer or importer_version()
    key = hashlib.sha256(f"{KEY_SCHEME}\0{inputs}\0{settings}\0{importer}".encode()).hexdigest()
    return {"key": key, "scheme": KEY_SCHEME, "inputsSha256": inputs, "settingsSha256": settings,
            "importer": importer, "dependencies": len(deps)}


def read_stamp(path: str) -> dict | None:
    """The build stamp stored in the collider ``path``, or None (no file, not readable, or not
    made by ``colossus build``).  Reads the one layer with ``Sdf`` (nothing composed), freshly
    from disk (never usd-core's layer cache)."""
    if not os.path.isfile(path):
        return None
    from pxr import Sdf

    try:
        layer = Sdf.Layer.OpenAsAnonymous(path)
    except Exception:
        return None
    if layer is None:
        return None
    todo = list(layer.rootPrims)
    while todo:
        spec = todo.pop()
        data = spec.customData.get("colossus") if spec.customData else None
        if isinstance(data, dict) and isinstance(data.get("build"), dict):
            return {str(k): v for k, v in data["build"].items()}
        todo.extend(spec.nameChildren)
    return None


CACHE_DIR = ".colossus_cache"


class StampCache:
    """``<project>/.colossus_cache/build.json``: the build key last seen in each output, with the
    output's (mtime_ns, size, inode) when it was seen (git's index, DVC's state), so a no-op
    ``build`` need not open 200 assets.  Only a shortcut: an output whose stat differs is read
    again (:func:`read_stamp`), and ``check`` always reads the asset itself."""

    def __init__(self, root: str):
        self.path = os.path.join(root, CACHE_DIR, "build.json")
        try:
            with open(self.path) as fh:
                self.data = json.load(fh)
            if not isinstance(self.data, dict):
                self.data = {}
        except (OSError, ValueError):
            self.data = {}
        self.dirty = False

    @staticmethod
    def _sig(path):
        try:
            st = os.stat(path)
        except OSError:
            return None
        return [st.st_mtime_ns, st.st_size, st.st_ino]

    def key(self, output: str) -> str | None:
        """The build key stored in ``output`` (None: no output, or none stored)."""
        sig = self._sig(output)
        if sig is None:
            return None
        hit = self.data.get(output)
        if isinstance(hit, list) and len(hit) == 4 and hit[:3] == sig:
            return hit[3]
        stamp = read_stamp(output)
        key = stamp.get("key") if stamp else None
        self.remember(output, key)
        return key

    def remember(self, output: str, key: str | None) -> None:
        sig = self._sig(output)
        if sig is None or key is None:
            self.dirty = self.data.pop(output, None) is not None or self.dirty
            return
        self.data[output] = sig + [key]
        self.dirty = True

    def save(self) -> None:
        """Write the cache (atomically; a cache that cannot be written is silently not kept)."""
        if not self.dirty:
            return
        from colossus.pipeline.tempfiles import write_atomic

        try:
            os.makedirs(os.path.dirname(self.path), exist_ok=True)
            gi = os.path.join(os.path.dirname(self.path), ".gitignore")
            if not os.path.exists(gi):
                with open(gi, "w") as fh:
                    fh.write("# made by colossus build: a cache, never committed\n*\n")
            write_atomic(self.path, json.dumps(self.data, sort_keys=True))
        except OSError:
            pass


def staleness(stamp: dict | None, want: dict) -> list:
    """What changed between the stored ``stamp`` and the ``want`` ed one: a list of ``source``,
    ``settings``, ``importer version`` (empty: up to date)."""
    if stamp is None:
        return ["no build key (not made by colossus build)"]
    if stamp.get("key") == want["key"]:
        return []
    out = []
    if stamp.get("inputsSha256") != want["inputsSha256"]:
        out.append("source changed")
    if stamp.get("settingsSha256") != want["settingsSha256"]:
        out.append("settings changed")
    if stamp.get("importer") != want["importer"]:
        out.append("importer version changed")
    return out or ["build key changed"]


def describe(entry: Entry, root: str) -> dict:
    """The resolved settings of one entry (``colossus config``)."""
    s = {k.replace("_", "-") if k != "meshes" else "mesh": v for k, v in asdict(entry.settings).items()}
    s["strict"] = entry.strict
    d = {"entry": entry.index, "name": entry.name, "source": os.path.relpath(entry.source, root),
         "output": os.path.relpath(entry.output, root), "import": s,
         "validate": {**{k.replace("_", "-"): v for k, v in entry.validate.items()}, "strict": entry.validate_strict}}
    if entry.waiver:
        d["waiver"] = entry.waiver
    return d
