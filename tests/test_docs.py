"""The README's generated sections (operators, presets, commands) match the code."""

from __future__ import annotations

from service import docs


def test_readme_generated_sections_are_current() -> None:
    text = docs.README.read_text()
    assert docs.render(text) == text, "README is stale: run `make docs`"


def test_every_operator_and_parameter_is_documented() -> None:
    from service.registry import operators

    section = docs.operators_section()
    for op in operators().values():
        assert f"### `{op.name}`" in section
        for name in op.params.model_fields:
            assert f"| `{name}` |" in section
