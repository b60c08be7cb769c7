"""Re-parameterisation after capture: list a session's model versions, add one (write scope)."""

from __future__ import annotations

from fastapi import APIRouter, Depends, HTTPException, Request
from pydantic import BaseModel, Field

from thermcap.api.routes.common import session_row
from thermcap.api.security import require
from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.exports.render import session_model
from thermcap.recorder.importers.dji_reparam import DJI_KINDS, add_sdk_version
from thermcap.recorder.importers.dji_sdk import find_backend
from thermcap.recorder.radiometry.params import ModelVersion, add_version, read_versions
from thermcap.recorder.storage.layout import DataRoot

router = APIRouter(prefix="/api/v1/sessions/{session_id}/radiometry", tags=["thermography"])


class NewVersion(BaseModel):
    params: dict[str, float] = Field(description="object parameters: emissivity, reflected_temp_c, ...")
    why: str = Field(min_length=1, description="kept with the version")
    who: str = Field("api", description="who asks (kept with the version)")
    frames: tuple[int, int] | None = Field(None, description="[start, end) frame indices; omitted: all")


@router.get("", dependencies=[Depends(require("read"))])
def list_versions(request: Request, session_id: str) -> dict:
    row = session_row(request, session_id)
    try:
        versions = read_versions(DataRoot.of(request.app.state.settings.root).session_dir(row["id"]))
    except ValueError as exc:
        raise HTTPException(500, str(exc)) from None
    return {"session": row["id"], "recorded_model": session_model(row["radiometric_model"]).to_dict(),
            "versions": [v.to_dict() for v in versions]}


@router.post("", status_code=201, dependencies=[Depends(require("write"))])
def new_version(request: Request, session_id: str, body: NewVersion) -> dict:
    row = session_row(request, session_id)
    session_dir = DataRoot.of(request.app.state.settings.root).session_dir(row["id"])
    if not session_dir.is_dir():
        raise HTTPException(409, f"session {row['id']} has no local folder here (served from the object store)")
    if body.frames is not None and not 0 <= body.frames[0] < body.frames[1] <= row["frames"]:
        raise HTTPException(400, f"frames must be [start, end) within 0..{row['frames']}")
    base = session_model(row["radiometric_model"])
    try:
        if getattr(base, "kind", "") in DJI_KINDS:
            v = _dji_version(session_dir, body)
        else:
            v = add_version(session_dir, base, body.params, who=body.who, why=body.why, frames=body.frames)
    except ValueError as exc:
        raise HTTPException(409 if "cannot be re-parameterised" in str(exc) else 400, str(exc)) from None
    return v.to_dict()


def _dji_version(session_dir, body: NewVersion) -> ModelVersion:
    """DJI's SDK measures the frames again (THERMCAP_DJI_SDK, or dji-thermal-cli on PATH)."""
    try:
        backend = find_backend("auto")
    except ThermcapError as exc:
        raise HTTPException(503, str(exc)) from None
    if backend is None:
        raise HTTPException(409, "a DJI session's object parameters are applied by DJI's SDK, which this server "
                                 "does not have (install dji-thermal-cli or set THERMCAP_DJI_SDK)")
    try:
        return add_sdk_version(session_dir, body.params, backend, who=body.who, why=body.why, frames=body.frames)
    except ThermcapError as exc:
        raise HTTPException(409, str(exc)) from None
