"""``tolsynth models``: the bundled models, each with its title and source."""

from __future__ import annotations

import re

from tolsynth.cli.args import add_table_out_argument, check_table_out, emit_json, inputs_record, write_out

__all__ = ["register", "model_rows"]


def model_rows() -> list[dict]:
    """One row per bundled model: name, title, source (first line), joints, error parameters, file."""
    from tolsynth.kinematics.mechanism import load_model
    from tolsynth.model.reader import bundled_models

    rows = []
    for name in bundled_models():
        m = load_model(name)
        source = " ".join(str(getattr(m.spec, "source", "") or "").split())
        rows.append(
            {
                "name": name,
                "title": m.title,
                "source": source,
                "source_line": _first_sentence(source),
                "joints": len(m.joint_names),
                "error_parameters": m.n,
                "configurations": ", ".join(m.configurations),
                "file": str(getattr(m.spec, "path", "") or ""),
            }
        )
    return rows


def _first_sentence(text: str, limit: int = 200) -> str:
    """The source's first sentence (initials such as "P. I. Corke" do not end it), at most ``limit``."""
    m = re.match(r"(.{40,}?[.;])\s", text)
    out = m.group(1) if m else text
    return out if len(out) <= limit else out[: limit - 3].rstrip() + "..."


def cmd_models(args) -> int:
    check_table_out(args)
    rows = model_rows()
    if args.out:
        from tolsynth.io.tables import make_frame

        write_out(make_frame(rows, "BundledModels", {}, {"count": len(rows)}), args)
    if args.json:
        emit_json({"models": rows, "inputs": inputs_record(args)})
        return 0
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        print(f"{r['name']:<{width}}  {r['title']}")
        print(
            f"{'':<{width}}  {r['joints']} joints, {r['error_parameters']} error parameters; "
            f"configurations: {r['configurations']}"
        )
        if r["source_line"]:
            print(f"{'':<{width}}  source: {r['source_line']}")
    print(f"{len(rows)} models; use one with --model NAME, or give a path to your own .toml file")
    return 0


def register(sub) -> None:
    """Add ``tolsynth models`` to the sub-command parser."""
    p = sub.add_parser(
        "models",
        help="list the bundled models with their source",
        description="The models shipped with tolsynth: name, title, joints, error parameters, "
        "named configurations and where their numbers come from.",
    )
    add_table_out_argument(p, "the list of models")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the list")
    p.set_defaults(func=cmd_models, task="the list of models")
