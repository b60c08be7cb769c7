"""``thermcap --config FILE`` (or ``$THERMCAP_CONFIG``): every command's defaults from one TOML file.

Each table is a command (``[record]``, ``[serve]``, ``[worker]``, ...), each key one of its
options, spelled as on the command line without the dashes (``max-disk = "20G"``; ``max_disk``
works too). Options given on the command line still win. A key the command does not have is an
error naming the file, the table and the key: a typo in an unattended box's config must not
silently fall back to a default. ``[[record.camera]]`` tables list a session's cameras, each
with a ``name``, a ``source`` and any per-camera key of ``--source``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import click

from thermcap.recorder.capture.sources.spec import CAMERA_KEYS, accepts_key

__all__ = ["load_config"]


def load_config(path: str | Path, group: click.Group, ctx: click.Context) -> dict[str, dict[str, Any]]:
    """The file as click's ``default_map``: {command: {parameter name: value}}."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise click.BadParameter(f"{p}: no such file", param_hint="--config") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise click.BadParameter(f"{p}: cannot read it ({exc})", param_hint="--config") from None
    except tomllib.TOMLDecodeError as exc:
        raise click.BadParameter(f"{p}: not valid TOML ({exc})", param_hint="--config") from None
    out: dict[str, dict[str, Any]] = {}
    for section, table in data.items():
        cmd = group.get_command(ctx, section)
        if cmd is None or not isinstance(table, dict):
            raise click.BadParameter(f"{p}: [{section}] is not a thermcap command "
                                     f"(commands: {', '.join(group.list_commands(ctx))})", param_hint="--config")
        out[section] = _command_defaults(p, section, cmd, table)
    return out


def _command_defaults(path: Path, section: str, cmd: click.Command, table: dict[str, Any]) -> dict[str, Any]:
    names: dict[str, click.Parameter] = {}
    for param in cmd.params:
        if not isinstance(param, click.Option) or param.name is None:
            continue
        names[param.name] = param
        for opt in param.opts + param.secondary_opts:
            names[opt.lstrip("-")] = param
            names[opt.lstrip("-").replace("-", "_")] = param
    out: dict[str, Any] = {}
    for key, value in table.items():
        if section == "record" and key == "camera":
            target = names["source"].name or "sources"
            out[target] = [_camera_spec(path, c) for c in (value if isinstance(value, list) else [value])]
            continue
        found = names.get(key)
        if found is None or found.name is None:
            raise click.BadParameter(f"{path}: [{section}] has no option {key!r} "
                                     f"(see `thermcap {section} --help`)", param_hint="--config")
        if getattr(found, "multiple", False) and not isinstance(value, list):
            value = [value]
        out[found.name] = value
    return out


def _camera_spec(path: Path, cam: Any) -> str:
    """A ``[[record.camera]]`` table as the ``--source`` text it stands for."""
    if not isinstance(cam, dict) or "source" not in cam:
        raise click.BadParameter(f"{path}: each [[record.camera]] needs a source (and a name)", param_hint="--config")
    extra = {k for k in set(cam) - {"name", "source"} if not accepts_key(str(cam["source"]), k)}
    gige = str(cam["source"]).startswith("gige:")
    if extra:
        raise click.BadParameter(f"{path}: [[record.camera]] {cam.get('name', '?')}: unknown keys "
                                 f"{', '.join(sorted(extra))} (allowed: name, source, {', '.join(CAMERA_KEYS)}"
                                 f"{'; a GigE camera also takes GenICam features' if gige else ''})",
                                 param_hint="--config")
    head = f"{cam['name']}={cam['source']}" if cam.get("name") else str(cam["source"])
    pairs = [f"{k.replace('_', '-')}={str(v).lower() if isinstance(v, bool) else v}"
             for k, v in cam.items() if k not in ("name", "source")]
    return ",".join([head, *pairs])
