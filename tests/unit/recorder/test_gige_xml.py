"""The camera's GenICam XML is exactly the bytes Aravis holds, by their size: PyGObject read the
unterminated buffer of a GigE device as a C string and ran past it (CI saw a UnicodeDecodeError
at byte 15,976 of a 15,975-byte XML, and no genicam.xml in the session)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from thermcap.recorder.capture.sources.gige import _genicam_xml

gi = pytest.importorskip("gi", reason="the gige extra (PyGObject) is not installed")


def _fake_device():
    try:
        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis
    except (ImportError, ValueError) as exc:
        pytest.skip(f"Aravis 0.8 is not installed ({exc})")
    return Aravis.FakeDevice.new("XMLTEST")


def test_the_xml_is_its_size_exactly_and_parses():
    device = _fake_device()
    data, problem = _genicam_xml(device)
    _, size = device.get_genicam_xml()
    assert problem == "" and len(data) == size
    assert ET.fromstring(data).tag.endswith("RegisterDescription")
