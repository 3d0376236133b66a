"""Write the service's OpenAPI contract: ``python -m service.openapi [PATH]``.

``openapi/openapi.json`` is generated from the app (routes, and one ``Pipeline`` branch per
registered operator) and committed; ``tests/test_api.py`` fails when the served schema differs
from it, so regenerate it after changing a route or an operator's parameters.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from service.http.app import create_app
from service.settings import Settings

DEFAULT_PATH = Path(__file__).resolve().parent.parent / "openapi" / "openapi.json"


def schema() -> dict[str, Any]:
    """The OpenAPI document of :func:`service.http.app.create_app` (independent of the
    settings)."""
    return create_app(Settings()).openapi()


def dumps(document: dict[str, Any]) -> str:
    """The committed text form: sorted keys would reorder routes, so insertion order, indent 2."""
    return json.dumps(document, indent=2, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0]) if args else DEFAULT_PATH
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps(schema()))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
