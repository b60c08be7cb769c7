"""Settings read in one place (issue 65's house): every ``THERMCAP_*`` variable is declared in
``recorder/settings.py`` with its default, read through that declaration, and listed on the
reference page. A module that names a variable itself fails here, so two readers cannot give one
variable two defaults (the region was "us-east-1" in five places)."""

from __future__ import annotations

import re
from pathlib import Path

from thermcap.recorder import settings

ROOT = Path(__file__).resolve().parents[3]
ROOMS = ("recorder", "archive", "api", "thermcap")
HOME = "recorder/settings.py"
#: a string that is exactly a variable's name: what reading one by hand needs
NAMED = re.compile(r"""["']THERMCAP_[A-Z0-9_]+["']""")
#: variables for benches and tests, never for a user's run
NOT_SETTINGS = {"THERMCAP_BENCH_LOOPBACK_NAMESPACE"}


def test_variables_are_named_in_the_settings_module_only():
    found = []
    for room in ROOMS:
        for path in sorted((ROOT / room).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel == HOME:
                continue
            for no, line in enumerate(path.read_text().splitlines(), 1):
                for m in NAMED.finditer(line):
                    if m.group(0).strip("\"'") not in NOT_SETTINGS:
                        found.append(f"{rel}:{no}: {line.strip()}")
    assert not found, "read through thermcap.recorder.settings instead:\n" + "\n".join(found)


def test_every_variable_is_on_the_reference_page():
    page = (ROOT / "docs" / "reference" / "cli-habits.md").read_text()
    listed = set(re.findall(r"^\| `(THERMCAP_[A-Z0-9_]+)` \|", page, re.M))
    assert listed == {v.name for v in settings.VARIABLES}


def test_a_default_is_the_same_for_every_reader(monkeypatch):
    from thermcap.api.settings import Settings

    for v in (settings.S3_REGION, settings.S3_PREFIX, settings.S3_BUCKET, settings.ROOT):
        monkeypatch.delenv(v.name, raising=False)
    monkeypatch.delenv("THERMCAP_TOKENS", raising=False)
    s = Settings()
    where = settings.BucketSettings.from_env()
    assert (s.s3_region, s.s3_prefix, s.s3_bucket) == (where.region, where.prefix, where.bucket) == \
        ("us-east-1", "", None)
    monkeypatch.setenv("THERMCAP_S3_REGION", "eu-central-1")
    assert Settings().s3_region == settings.BucketSettings.from_env().region == "eu-central-1"
