"""mkdocs hook: the HTTP reference page is generated from the service's own OpenAPI document,
so it lists exactly the routes, parameters and media types the code serves."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

MARK = "<!-- openapi-routes -->"


def _routes() -> str:
    from thermcap.api.app import create_app
    from thermcap.api.settings import Settings

    with tempfile.TemporaryDirectory() as tmp:
        doc = create_app(Settings(root=Path(tmp))).openapi()
    out: list[str] = []
    by_tag: dict[str, list[tuple[str, str, dict[str, Any]]]] = {}
    for path, methods in doc["paths"].items():
        for method, op in methods.items():
            by_tag.setdefault((op.get("tags") or ["other"])[0], []).append((method.upper(), path, op))
    for tag in sorted(by_tag):
        out.append(f"## {tag}\n")
        out.append("| method | path | what | parameters | answers |\n|---|---|---|---|---|")
        for method, path, op in sorted(by_tag[tag], key=lambda r: (r[1], r[0])):
            what = (op.get("summary") or op.get("description") or "").split("\n")[0].replace("|", "\\|")
            params = ", ".join(f"`{p['name']}`" for p in op.get("parameters", []) if p.get("in") == "query")
            answers = "; ".join(f"{code}: {', '.join(r.get('content', {}) or ['-'])}"
                                for code, r in sorted(op.get("responses", {}).items()) if code.startswith("2"))
            out.append(f"| {method} | `{path}` | {what} | {params} | {answers} |")
        out.append("")
    return "\n".join(out)


def on_page_markdown(markdown: str, **_: Any) -> str:
    return markdown.replace(MARK, _routes()) if MARK in markdown else markdown
