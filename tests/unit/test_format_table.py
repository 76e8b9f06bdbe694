"""The output formats' one table (prismcore.formats): what the spec, the worker and the page read
from it agrees with it, and it loads without numpy, as the spec does."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import get_args

import pytest
from pydantic import ValidationError

from prismcore.formats import FILE_NAMES, FILES, FORMAT_TABLE, METRIC_FORMATS, media_type, output_files
from prismcore.spec import OutputFormat, ScanSpec

ROOT = Path(__file__).resolve().parents[2]


def test_the_spec_asks_for_the_tables_formats():
    assert get_args(OutputFormat) == tuple(FORMAT_TABLE)
    schema = ScanSpec.model_json_schema()
    items = schema["properties"]["formats"]["items"]
    assert items["enum"] == list(FORMAT_TABLE)


def test_every_file_a_format_writes_has_its_name_and_media_type():
    for kind in output_files(list(FORMAT_TABLE)):
        assert FILE_NAMES[kind] == FILES[kind].name
        assert "/" in media_type(kind)
    assert set(FILE_NAMES) == set(FILES)
    assert len(set(FILE_NAMES.values())) == len(FILE_NAMES), "two kinds share a file name"


def test_an_unknown_kind_has_no_media_type():
    with pytest.raises(KeyError):
        media_type("not_a_kind")


POINTS = [[395, 293], [943, 331], [919, 761], [943, 331], [1035, 298], [411, 647], [1009, 660]]


@pytest.mark.parametrize("fmt", list(FORMAT_TABLE))
def test_a_scale_is_needed_exactly_where_the_table_says(fmt):
    spec = {"image": "a.jpg", "points": POINTS, "formats": [fmt]}
    if FORMAT_TABLE[fmt].needs_scale:
        assert fmt in METRIC_FORMATS
        with pytest.raises(ValidationError, match=r"need a scale|give a scale"):
            ScanSpec.model_validate(spec)
    else:
        assert ScanSpec.model_validate(spec).formats == [fmt]
    assert ScanSpec.model_validate({**spec, "scale": {"kind": "mm_per_px", "front": 0.2}}).formats == [fmt]


def test_the_table_loads_without_numpy():
    code = "import sys, prismcore.formats; print('numpy' in sys.modules, 'cv2' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_the_page_reads_the_table():
    # web/src/formats.ts is generated from the table (scripts/build-web runs the generator):
    # the committed file is the table's, and no other page source keeps a list of formats.
    done = subprocess.run([str(ROOT / "scripts" / "web-formats"), "--check"], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    lists = re.compile(r"\[\s*\"(las|laz|glb|step)\"")
    for source in (ROOT / "web" / "src").glob("*.ts"):
        if source.name != "formats.ts":
            assert not lists.search(source.read_text()), f"{source.name} lists formats: read ./formats"


def test_the_reference_page_lists_the_tables_formats():
    page = (ROOT / "docs" / "reference" / "outputs.md").read_text()
    section = page.split("\n## Formats\n", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `(\w+)` \| (.+) \| (yes|no) \|$", section, re.M)
    documented = {fmt: (re.findall(r"`([^`]+)`", files), needs == "yes") for fmt, files, needs in rows}
    assert documented == {fmt: ([FILE_NAMES[kind] for kind in row.files], row.needs_scale)
                          for fmt, row in FORMAT_TABLE.items()}


def test_the_architecture_page_names_the_format_table_and_the_sink():
    """What the architecture page says a new format and a scan's files go through is there: the
    format table, its writer's branch, the sink and `write_outputs`."""
    import importlib

    page = (ROOT / "docs" / "explanation" / "architecture.md").read_text(encoding="utf-8")
    section = page.split("## Where a new feature goes", 1)[1]
    named = set(re.findall(r"`((?:formats|outputs)(?:\.\w+)+)`", section))
    assert {"formats.FORMAT_TABLE", "formats.FILES", "formats.OutputFormat", "outputs.writers.write_format",
            "outputs.sink.Sink"} <= named
    for dotted in named:
        module, _, name = dotted.rpartition(".")
        assert hasattr(importlib.import_module(f"prismcore.{module}"), name), dotted
    assert "`write_outputs`" in section
    from prismcore.outputs import write_outputs

    assert callable(write_outputs)
