"""The README's reference sections, generated: ``python -m service.docs [README.md]``.

The operator reference comes from the registry, the preset table from :data:`gbuffer.PRESETS`
and the command list from the ``depict`` parser, so they cannot drift from the code;
``tests/test_docs.py`` fails when the committed README differs from what this writes. Each section
sits between ``<!-- NAME -->`` and ``<!-- /NAME -->``.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from gbuffer.presets import PRESETS
from service.cli import build_parser
from service.masks import MASK_FIELDS
from service.registry import Params, operators

README = Path(__file__).resolve().parent.parent / "README.md"


def _default(field: Any) -> str:
    if field.default_factory is not None:
        value = field.default_factory()
    else:
        value = field.default
    if value is None:
        return "–"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, int | float):
        return f"{value:g}"
    return f"`{value}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def operators_section() -> str:
    """Every operator: summary, what it needs and writes, its parameters."""
    lines = [
        "## Operators",
        "",
        "Every operator below is a step of a pipeline (`depict enhance --op NAME --set k=v`, "
        "`--pipeline PIPE.json`, the `pipeline` field of `POST /v1/enhance`). `depict ops` "
        "prints this list; `GET /v1/operators` gives the JSON schemas. Sizes are relative to the "
        "image height unless they say scene units.",
    ]
    for op in operators().values():
        lines += ["", f"### `{op.name}`", "", op.summary[0].upper() + op.summary[1:] + ".", ""]
        lines.append(
            f"Needs {', '.join(f'`{n}`' for n in op.needs) or 'nothing'}; "
            f"writes {', '.join(f'`{w}`' for w in op.writes)}."
        )
        lines += _table({k: v for k, v in op.params.model_fields.items() if k not in MASK_FIELDS})
    lines += [
        "",
        "### Masks (every operator)",
        "",
        "Every step also takes these parameters, which restrict it to a matte m in [0, 1]: "
        "out = in + m·(op(in) − in) for every layer the step writes (zero for a layer it "
        "adds). `depict mask FILE SPEC -o m.png` writes the matte; `depict inspect` lists the "
        "file's Cryptomatte names; `depict preview --layer cryptomatte` shows their ids.",
    ]
    lines += _table({k: v for k, v in Params.model_fields.items() if k in MASK_FIELDS})
    return "\n".join(lines)


def _table(fields: dict[str, Any]) -> list[str]:
    lines = ["", "| parameter | default | meaning |", "|---|---|---|"]
    for name, field in fields.items():
        lines.append(f"| `{name}` | {_cell(_default(field))} | {_cell(field.description or '')} |")
    return lines


def presets_section() -> str:
    """Each renderer preset with the layer names it maps."""
    lines = [
        "## Renderer presets",
        "",
        "`--preset auto` (the default) picks one from the header and channel names and "
        "`depict inspect` says which and why. The first layer name found wins; "
        "`--map BUFFER=LAYER` overrides any of them.",
        "",
        "| preset | renderer | normal (space) | depth | beauty | lobes (light × colour) |",
        "|---|---|---|---|---|---|",
    ]
    for name, preset in PRESETS.items():
        normal = ", ".join(f"`{layer}` ({space})" for layer, space in preset.normal) or "–"
        depth = ", ".join(f"`{d}`" for d in preset.buffers.get("depth", ())) or "–"
        depth += f" ({preset.depth_kind})"
        beauty = ", ".join(f"`{b or '(R,G,B)'}`" for b in preset.buffers.get("beauty", ())) or "–"
        lobes = []
        for lobe, spec in preset.lobes.items():
            light = spec.light[0] if spec.light else spec.radiance[0] if spec.radiance else ()
            parts = "+".join(light)
            color = f" × {spec.color[0]}" if spec.color else ""
            lobes.append(f"{lobe}: `{parts}{color}`")
        lines.append(
            f"| `{name}` | {_cell(preset.description)} | {normal} | {depth} | {beauty} | "
            f"{_cell('; '.join(lobes)) or '–'} |"
        )
    return "\n".join(lines)


def cli_section() -> str:
    """The commands of ``depict`` with their one-line help."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {a.dest: a.help for a in sub._choices_actions}
    lines = [
        "## Commands",
        "",
        "`depict COMMAND --help` lists every flag. Commands that process frames (`enhance`, "
        "`render`, `score`, `compare`, `relief-pick`) run locally, or on a Depict server with "
        "`--server URL` (or `DEPICT_SERVER`) with the same flags and the same output; a flag "
        "the server's route does not take is refused rather than dropped (`render --shading`; "
        "`--map`, `--normal-space`, `--view-layer` and `--colorspace` of `compare` and "
        "`relief-pick`).",
        "",
        "| command | what it does |",
        "|---|---|",
    ]
    for name in sub.choices:
        lines.append(f"| `depict {name}` | {_cell(helps.get(name) or '')} |")
    return "\n".join(lines)


SECTIONS: dict[str, Callable[[], str]] = {
    "CLI": cli_section,
    "OPERATORS": operators_section,
    "PRESETS": presets_section,
}


def render(text: str) -> str:
    """``text`` with every generated section replaced by its current contents."""
    for name, make in SECTIONS.items():
        pattern = re.compile(rf"<!-- {name} -->\n.*?<!-- /{name} -->", re.DOTALL)
        found = pattern.search(text)
        if not found:
            raise ValueError(f"README has no <!-- {name} --> ... <!-- /{name} --> section")
        block = f"<!-- {name} -->\n{make()}\n<!-- /{name} -->"
        text = text[: found.start()] + block + text[found.end() :]
    return text


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0]) if args else README
    path.write_text(render(path.read_text()))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
