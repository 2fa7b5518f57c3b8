"""Pages generated from the code at build time, so that they cannot drift from it:
``_generated/cli.md`` (every sub-command's ``--help``) and ``_generated/format_keys.md`` (every
table and key of :data:`tolsynth.model.fields.FORMAT`); and the folder of the notebooks' executed
outputs, shared with ``tests/test_notebooks.py`` (:func:`notebook_cache_dir`)."""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parent / "_generated"
ROOT = Path(__file__).resolve().parent.parent


def notebook_cache_dir() -> Path:
    """The jupyter-cache folder of the executed notebooks for this package's source.

    jupyter-cache keys each executed notebook by its code cells; the folder adds the package's
    source, the model files and the Python version to the key, so a cached page always shows
    what the current code computes. The test that executes a notebook stores it here, and the docs
    build reads it back instead of executing the notebook a second time.
    """
    digest = hashlib.sha256(sys.version.encode())
    for path in sorted([*(ROOT / "tolsynth").rglob("*.py"), *(ROOT / "models").glob("*.toml")]):
        digest.update(path.relative_to(ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    return ROOT / "docs" / "_build" / ".jupyter_cache" / digest.hexdigest()[:16]


def _write(name: str, text: str) -> None:
    OUT.mkdir(exist_ok=True)
    path = OUT / name
    if not path.exists() or path.read_text(encoding="utf-8") != text:  # unchanged: no rebuild
        path.write_text(text, encoding="utf-8")


def cli_page() -> str:
    from tolsynth.cli import build_parser

    parser = build_parser()
    parser.prog = "tolsynth"
    out = ["```text", parser.format_help().rstrip(), "```", ""]
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, p in sub.choices.items():
        out += [f"## tolsynth {name}", "", "```text", p.format_help().rstrip(), "```", ""]
    return "\n".join(out)


def format_page() -> str:
    from tolsynth.model.fields import FORMAT

    out = ["| table | required keys | optional keys |", "|---|---|---|"]
    for table, keys in FORMAT.items():
        req = ", ".join(f"`{k}`" for k, r in keys.items() if r) or "-"
        opt = ", ".join(f"`{k}`" for k, r in keys.items() if not r) or "-"
        out.append(f"| {'(top level)' if table == '' else '`' + table + '`'} | {req} | {opt} |")
    return "\n".join(out) + "\n"


def _generate(app) -> None:
    import os

    os.environ.setdefault("COLUMNS", "100")  # argparse wraps the help at the terminal width
    _write("cli.md", cli_page())
    _write("format_keys.md", format_page())


def setup(app):
    app.connect("builder-inited", _generate)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
