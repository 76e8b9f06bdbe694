"""Every command the README and the docs site (docs/**/*.md) show is run here, as written.

Their `sh` blocks are what a user types; `text` blocks are output or usage synopses with
placeholders, `json` and `python` blocks data and code (the python blocks are run too). Each
`sh` block must be claimed by one of the runners below, so a block added without a test fails
this file. The only changes made to a block before it runs: the key placeholder `k-...` becomes
the key this test's `prism serve` generated, and the API's port 8000 becomes this test's port
(the server and client commands are pointed at it through their documented environment
variables), and the webhook receiver's port 8080 becomes a free one. A few blocks cannot run
here and are checked instead of run, each saying so below: `docker compose` and `kubectl` (no
Docker engine or cluster), a test file run on its own (the suite runs it), `scripts/test` and
`scripts/test-cluster` (CI runs them).
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import signal
import subprocess
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from prismsynth import Box
from prismsynth.video import moving_clip

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]
SITE = ROOT / "services" / "api" / "guide"
_BLOCK = re.compile(r"^```(\w+)\n(.*?)^```$", re.S | re.M)
SAMPLE_SIZE = (120.0, 80.0, 60.0)  # samples/box.jpg's box, mm
_SIZE = r"([\d.]+) (?:± ([\d.]+)|\(given\))"  # a known edge prints as "120.00 (given)"
_MEASURED = re.compile(rf"item \d+: succeeded  {_SIZE} x {_SIZE} x {_SIZE} mm")


def measured_within_sigma(out: str, size: tuple[float, float, float] = SAMPLE_SIZE) -> int:
    """How many items `out` shows measured; each must hold the true size within its printed ±."""
    found = _MEASURED.findall(out)
    for groups in found:
        for value, sigma, true in zip(groups[::2], groups[1::2], size, strict=True):
            allowed = float(sigma) if sigma else 0.0  # a given edge is the length given
            assert abs(float(value) - true) <= allowed + 0.01, (groups, out)  # 0.01: the printed rounding
    return len(found)


def _serve_ready(argv: list[str], env: dict[str, str], log_path: Path, timeout: float = 240,
                 ) -> tuple[subprocess.Popen[bytes], int]:
    """Start `argv` (a `prism serve`, or a block that runs one) on env's PRISM_SERVE_PORT and wait
    for its 'ready: API' line. A port free when picked can be taken by another process before the
    API binds it (a fresh-clone run beside a CPU burner met it: 'process exited with 3 before port
    ... opened'): then again on another free port, up to three times. Returns the process and its
    API port."""
    from prism_cli.stack import free_port

    for _ in range(3):
        port = int(env["PRISM_SERVE_PORT"])
        with log_path.open("w") as sink:  # the child keeps its own copy
            proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=sink, stderr=subprocess.STDOUT,
                                    start_new_session=True)
        deadline = time.monotonic() + timeout
        while "ready: API" not in log_path.read_text() and proc.poll() is None:
            assert time.monotonic() < deadline, log_path.read_text()
            time.sleep(0.3)
        if "ready: API" in log_path.read_text():
            return proc, port
        text = log_path.read_text()
        assert f"before port {port} opened" in text, text  # any other exit fails the test
        env["PRISM_SERVE_PORT"] = str(free_port())
    raise AssertionError(f"no free API port in 3 tries: {log_path.read_text()}")


def blocks(lang: str) -> list[tuple[Path, str]]:
    return [(page, body) for page in PAGES for kind, body in _BLOCK.findall(page.read_text()) if kind == lang]


def sh_blocks() -> list[str]:
    return [body for _, body in blocks("sh")]


def python_block(marker: str) -> str:
    found = {body for _, body in blocks("python") if marker in body}
    assert len(found) == 1, f"docs: expected one python block containing {marker!r}, found {len(found)}"
    return found.pop()


def _blocks(marker: str) -> list[str]:
    """The distinct sh blocks holding `marker` (a block shown on two pages is run once)."""
    found = list(dict.fromkeys(b for b in sh_blocks() if marker in b))
    assert found, f"docs: no sh block contains {marker!r}"
    return found


def _block(marker: str) -> str:
    found = _blocks(marker)
    assert len(found) == 1, f"docs: expected one sh block containing {marker!r}, found {found}"
    return found[0]


def _bash(script: str, *, cwd: Path, env: dict[str, str], timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _table_fields(page: Path, heading: str) -> set[str]:
    """The names in the first column of the table under `## heading` in `page`."""
    section = page.read_text().split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]
    cells = re.findall(r"^\| (`[^|]*`) \|", section, re.M)
    return {name for cell in cells for name in re.findall(r"`(\w+)`", cell)}


OUTPUTS = ROOT / "docs" / "reference" / "outputs.md"

# Each runner claims the blocks holding its marker.
MARKERS = {
    "two commands": "scripts/demo",
    "local scan": "--focal-px 1400 --distance-mm 279.132",
    "exit codes": 'echo "exit $?"',
    "several photos": "--points-file",
    "video": "render_clip",
    "tracked video": "--points-frame",
    "calibrate": "prism calibrate",
    "serve": "&& .venv/bin/prism serve",
    "webhook secret": "export PRISM_WEBHOOK_SECRET=",
    "webhooks serve": "PRISM_WEBHOOK_ALLOW_PRIVATE=true",
    "webhook submit": "--webhook http://127.0.0.1:8080/",
    "client": "export PRISM_API_KEY=k-...",
    "curl": "curl ",
    "mistakes": "refused (exit",
    "lock": "scripts/lock",
    "docs": "scripts/docs",
    "k8s render": "render.py --check",
    "kubectl": "kubectl ",
    "compose": "docker compose",
    "a test file": "-m pytest ",
    "cluster": "scripts/test-cluster",
    "station": "prism station calibrate --board station-sample/",
    "station batch": "--station station.json --out out/parts",
    "points table": "--points-table",
    "station verify": "prism station verify station.json",
    "station upload": "prism station upload station.json",
    "station submit": "prism submit --station",
    "certify": "line1.json",
    "photo to cad": "--format step,drawing",
    "cad without a scale": "--out out/no-scale",
}


def test_every_sh_block_is_run_by_a_test():
    for body in sh_blocks():
        claims = [name for name, marker in MARKERS.items() if marker in body]
        assert len(claims) == 1, f"docs sh block claimed by {claims or 'no test'}: {body}"
    for marker in MARKERS.values():
        _blocks(marker)


def test_no_page_names_an_issue():
    for page in PAGES:
        text = page.read_text()
        assert not re.search(r"\bissues? \d+", text, re.I), f"{page} names an issue number"


def test_every_benchmark_command_named_exists_with_its_flags():
    """The figures' commands (inline in the explanation pages' tables): each script is there and
    takes each flag named."""
    named = 0
    for page in PAGES:
        for script, args in re.findall(r"`\.venv/bin/python (benchmarks/\w+\.py)([^`]*)`", page.read_text()):
            source = (ROOT / script).read_text()
            for flag in re.findall(r"--[\w-]+", args):
                assert f'"{flag}"' in source, f"{page.name}: {script} has no {flag}"
            named += 1
    assert named >= 10


@pytest.fixture
def user_dir(tmp_path: Path) -> Path:
    """A folder like the repository's top as a user's shell sees it (samples, .venv), whose
    outputs (`out/...`) land in the test's temporary folder."""
    for name in ("samples", ".venv", "README.md"):
        (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


def test_two_commands_block():
    lines = {line.split("#")[0].strip() for block in _blocks(MARKERS["two commands"])
             for line in block.splitlines() if line.strip()}
    assert lines == {"scripts/demo", "scripts/test"}, lines
    # scripts/test is what CI runs (.ci/run runs it, then scripts/test-cluster), so it runs on
    # every submission; running it from inside the suite would recurse.
    assert "scripts/test" in (ROOT / ".ci" / "run").read_text().splitlines()
    run = _bash("scripts/demo", cwd=ROOT, env=dict(os.environ), timeout=600)
    assert run.returncode == 0, run.stderr
    report = json.loads((ROOT / "out" / "demo" / "report.json").read_text())
    assert report["dimensions"]["unit"] == "mm"
    # The demo says what the sample truly measures, beside what it measured, and the error.
    dims = report["dimensions"]
    assert "true size       120 x 80 x 60 mm" in run.stdout, run.stdout
    measured = " x ".join(f"{dims[d]:.2f}" for d in ("width", "height", "depth"))
    assert f"measured        {measured} mm" in run.stdout, run.stdout
    error = next(line for line in run.stdout.splitlines() if line.startswith("error"))
    for d, true in zip(("width", "height", "depth"), SAMPLE_SIZE, strict=True):
        assert f"{d} {dims[d] - true:+.2f} mm ({100 * (dims[d] - true) / true:+.2f} %" in error, error
    # The README shows the demo's last lines as they are.
    shown = [b for _, b in blocks("text") if b.startswith("true size")]
    assert shown and shown[0].splitlines() == run.stdout.strip().splitlines()[-3:], (shown, run.stdout)


def test_lock_block_is_the_command_test_lock_runs():
    # Running it rewrites the locks, so tests/test_lock.py runs it on a copy of the repository
    # and requires the committed locks back unchanged.
    block = _block(MARKERS["lock"])
    assert [line.split("#")[0].strip() for line in block.splitlines() if line.strip()] == ["scripts/lock"]
    assert '["scripts/lock"]' in (ROOT / "tests" / "test_lock.py").read_text()


def test_local_scan_block(user_dir: Path):
    for block in _blocks(MARKERS["local scan"]):  # the README's and the first tutorial's
        run = _bash(block, cwd=user_dir, env=dict(os.environ), timeout=300)
        assert run.returncode == 0, run.stderr
        assert "120.01 ± 1.01 x 79.99 ± 0.79 x 59.99 ± 0.85 mm" in run.stdout, run.stdout
    report = json.loads((user_dir / "out" / "box" / "report.json").read_text())
    assert report["dimensions"]["unit"] == "mm"
    assert (user_dir / "out" / "box" / "cloud.ply").stat().st_size > 0
    # Every field of report.json is in the reference's table.
    documented = _table_fields(OUTPUTS, "report.json")
    assert set(report) <= documented, set(report) - documented


def test_photo_to_cad_blocks_write_the_solid_and_the_drawing_and_refuse_pixels(user_dir: Path):
    page = ROOT / "docs" / "how-to" / "photo-to-cad.md"
    run = _bash(_block(MARKERS["photo to cad"]), cwd=user_dir, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stderr
    shown = next(b for p, b in blocks("text") if p == page and b.startswith("639,716 points"))
    assert run.stdout.strip().splitlines() == shown.strip().splitlines(), run.stdout
    out = user_dir / "out" / "cad"
    report = json.loads((out / "report.json").read_text())
    size = [report["dimensions"][d] for d in ("width", "height", "depth")]
    # the page's python block reads the solid back with the kernel: the box measured
    script = user_dir / "read_step.py"
    script.write_text(python_block('reader.ReadFile("out/cad/part.step")'))
    read = subprocess.run([str(ROOT / ".venv" / "bin" / "python"), str(script)], cwd=user_dir,
                          capture_output=True, text=True, timeout=120)
    assert read.returncode == 0, read.stderr
    assert read.stdout.strip() == (" x ".join(f"{v:.4f}" for v in size)
                                   + f" mm, {math.prod(size) / 1000:.1f} cm3"), read.stdout
    # every field of part.step.json is in the reference's table
    meta = json.loads((out / "part.step.json").read_text())
    documented = _table_fields(OUTPUTS, "part.step.json")
    assert set(meta) <= documented, set(meta) - documented
    assert (ROOT / "docs" / "assets" / "drawing.png").stat().st_size > 10_000  # the page's picture
    refused = _bash(_block(MARKERS["cad without a scale"]), cwd=user_dir, env=dict(os.environ), timeout=120)
    assert refused.returncode == 0 and refused.stderr.count("\n") == 1, refused.stderr
    assert refused.stderr.strip() in [b.strip() for p, b in blocks("text") if p == page], refused.stderr
    assert not (user_dir / "out" / "no-scale" / "part.step").exists()


def test_exit_codes_block_exits_2_in_one_line(user_dir: Path):
    run = _bash(_block(MARKERS["exit codes"]), cwd=user_dir, env=dict(os.environ), timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "exit 2", run.stdout + run.stderr
    assert run.stderr.strip().count("\n") == 0 and run.stderr.startswith("prism: error:"), run.stderr
    shown = ROOT / "docs" / "reference" / "exit-codes.md"
    assert run.stderr.strip() in shown.read_text(), run.stderr


def test_several_photos_block_measures_one_box(user_dir: Path):
    run = _bash(_block(MARKERS["several photos"]), cwd=user_dir, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "3 of 3 views as one box" in run.stdout, run.stdout
    joint = json.loads((user_dir / "out" / "part" / "joint" / "joint.json").read_text())
    for value, sigma, true in zip((joint["dimensions"][d] for d in ("width", "height", "depth")),
                                  (joint["uncertainty"][d] for d in ("width", "height", "depth")),
                                  SAMPLE_SIZE, strict=True):
        assert abs(value - true) <= 2 * sigma + 0.05, joint
    assert set(joint) <= _table_fields(OUTPUTS, "joint.json"), set(joint)


def test_points_table_block_measures_two_parts_each_alone(user_dir: Path):
    run = _bash(_block(MARKERS["points table"]), cwd=user_dir, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "2 of 2 photos measured" in run.stdout, run.stdout
    with (user_dir / "out" / "lot" / "measured" / "results.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["item_reference"], r["file_name"], r["state"]) for r in rows] == [
        ("part-A", "box.jpg", "succeeded"), ("part-B", "box.jpg", "succeeded")]
    for row, size in zip(rows, (SAMPLE_SIZE, (150.0, 60.0, 40.0)), strict=True):
        for d, true in zip(("width", "height", "depth"), size, strict=True):
            assert abs(float(row[d]) - true) <= 2 * float(row[f"{d}_sigma"]) + 0.05, row
    assert (user_dir / "out" / "lot" / "measured" / "box-2" / "report.json").is_file()


def test_tracked_video_block_tracks_and_measures_the_frames(user_dir: Path):
    run = _bash(_block(MARKERS["tracked video"]), cwd=user_dir, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    scan = user_dir / "out" / "tracked" / "scan"
    # The oracle: the renderer's own corners of each selected frame (the block marks frame 6's).
    _, corners = moving_clip(Box(120, 80, 60), 13, image_size=(640, 360), focal_px=600, seed=0)
    tracked = json.loads((scan / "tracked_points.json").read_text())
    assert sorted(map(int, tracked)) == [0, 4, 8, 12], tracked
    for index, entry in tracked.items():
        worst = max(math.dist(p, q) for p, q in zip(entry["points"], corners[int(index)], strict=True))
        assert worst < 2.0, (index, worst)
    summary = json.loads((scan / "summary.json").read_text())
    assert summary["frames"] == {"selected": 4, "measured": 4, "failed": 0}, summary
    assert summary["tracking"]["tracked"] == [0, 4, 8, 12]
    for name, true_mm in (("height", 80.0), ("depth", 60.0)):
        assert abs(summary["dimensions"][name]["median"] / true_mm - 1) < 0.02, summary["dimensions"]


def test_video_block_measures_the_frames(user_dir: Path):
    run = _bash(_block(MARKERS["video"]), cwd=user_dir, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    scan = user_dir / "out" / "video" / "scan"
    summary = json.loads((scan / "summary.json").read_text())
    assert summary["frames"] == {"selected": 4, "measured": 4, "failed": 0}, summary
    assert summary["dimensions"]["height"]["median"] == pytest.approx(80, rel=0.01)
    assert set(summary) <= _table_fields(OUTPUTS, "summary.json"), set(summary)
    report = json.loads((scan / "frame_000005" / "report.json").read_text())
    assert set(report) <= _table_fields(OUTPUTS, "report.json"), set(report)


def test_calibrate_block_calibrates_on_opencvs_photos(user_dir: Path):
    if not Path("/usr/share/doc/opencv-doc/examples/data/left01.jpg").is_file():
        pytest.fail("Debian's opencv-doc is missing: run scripts/setup as root")
    run = _bash(_block(MARKERS["calibrate"]), cwd=user_dir, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "views used     13 of 13" in run.stdout, run.stdout
    camera = json.loads((user_dir / "out" / "camera.json").read_text())
    assert camera["fx"] == pytest.approx(533.2, abs=1)


def _true_sizes(folder: Path) -> dict[str, dict[str, float]]:
    """`prism sample --station`'s true_sizes.csv: each photo's part, as the station reports it."""
    with (folder / "true_sizes.csv").open() as source:
        return {row["photo"]: {k: float(row[f"{k}_mm"]) for k in ("width", "depth", "height")}
                for row in csv.DictReader(source)}


def test_station_block_measures_parts_with_no_click(user_dir: Path):
    """The station blocks as a user with no camera runs them: `prism sample --station` renders the
    board's photos (prism board's default board), the calibration, a part and a hand-held photo
    of a part lying on the board, each measured within max(2 %, 1.5 mm) of the size the sample's
    true_sizes.csv gives; the batch block (the parts and the empty support in one command); then
    the verify block on the sample's reference part: verified, as the how-to shows it (and, as it
    says, not verified against +-0.5 mm)."""
    for block in _blocks(MARKERS["station"]):
        run = _bash(block, cwd=user_dir, env=dict(os.environ), timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        truth = _true_sizes(user_dir / "station-sample")
        for out, photo in (("part", "parts/1.jpg"), ("handheld", "handheld.jpg")):
            report = json.loads((user_dir / "out" / out / "report.json").read_text())
            for key, true in truth[photo].items():
                assert abs(report["dimensions"][key] - true) <= max(0.02 * true, 1.5), (out, key, report)
    # The batch block: every part measured within the same bounds, the empty support named as
    # failed with its reason (exit 1), and a row each in results.csv.
    run = _bash(_block(MARKERS["station batch"]), cwd=user_dir, env=dict(os.environ), timeout=600)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "[7/7] station-sample/empty.jpg  failed: no part found" in run.stdout, run.stdout
    assert "6 of 7 photos measured" in run.stdout, run.stdout
    with (user_dir / "out" / "parts" / "results.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["state"] for r in rows] == ["succeeded"] * 6 + ["failed"], rows
    for row in rows[:6]:
        for key, true in truth[f"parts/{row['file_name']}"].items():
            assert abs(float(row[key]) - true) <= max(0.02 * true, 1.5), row
    assert rows[6]["error"].startswith("no part found on the support"), rows[6]
    env = {**os.environ, "COLUMNS": "300"}
    for block in _blocks(MARKERS["station verify"]):
        run = _bash(block, cwd=user_dir, env=env, timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        stored = json.loads((user_dir / "station.json").read_text())["verification"]
        assert stored["verified"] is True
        assert stored["reference_mm"] == {"width": 70, "depth": 45, "height": 30}
    shown = next(b for _, b in blocks("text") if b.lstrip().startswith("reference    bias"))
    undated = re.compile(r"\d{4}-\d\d-\d\d")
    printed = {undated.sub("DATE", line) for line in run.stdout.splitlines()}
    for line in shown.splitlines():
        assert undated.sub("DATE", line) in printed, (line, run.stdout)
    tight = _bash(block.replace("--tolerance 2", "--tolerance 0.3"), cwd=user_dir, env=env, timeout=600)
    assert tight.returncode == 1, tight.stdout + tight.stderr
    # the page's words: a scatter of 0.05 mm is 51 % of a 0.6 mm tolerance's width
    grr = re.search(r"\n  width: %GRR (\d+\.\d) % is over 30 %", tight.stdout)
    assert grr and 45 <= float(grr.group(1)) <= 55, tight.stdout


def test_docs_block_builds_the_site_strictly_offline():
    """scripts/docs: mkdocs --strict (a broken link or a warning fails), every generated
    reference page made from the code, nothing loaded from another origin."""
    assert _block(MARKERS["docs"]).split("#")[0].strip() == "scripts/docs"
    started = time.monotonic()
    run = _bash("scripts/docs", cwd=ROOT, env=dict(os.environ), timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    print(f"\nscripts/docs built the site in {time.monotonic() - started:.1f} s")
    import typer.main

    from prism_cli.main import cli

    cli_page = (SITE / "reference" / "cli" / "index.html").read_text()
    for name in typer.main.get_command(cli).commands:
        assert f'id="prism-{name}"' in cli_page, name
    assert "POST /v1/jobs" in (SITE / "reference" / "http-api" / "index.html").read_text()
    assert "PRISM_DEFAULT_FORMATS" in (SITE / "reference" / "configuration" / "index.html").read_text()
    assert "backend-unavailable" in (SITE / "reference" / "problems" / "index.html").read_text()
    assert "views" in (SITE / "reference" / "job-spec" / "index.html").read_text()
    elsewhere = re.compile(r"""(src|href)=["']?(https?:)?//[^"' >]*\.(js|css|woff2?)\b""")
    for page in SITE.rglob("*.html"):
        text = page.read_text()
        assert not elsewhere.search(text), page
        assert "fonts.googleapis" not in text, page
        # The generated pages too (help texts, the API's descriptions) name no issue.
        assert not re.search(r"\bissues? \d+", text, re.I), page


def test_k8s_render_block_finds_the_manifest_current():
    run = _bash(_block(MARKERS["k8s render"]), cwd=ROOT, env=dict(os.environ), timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr


def test_kubectl_block_is_checked_not_run():
    """No cluster here: the block parses, and the file it applies and the keys it sets are the
    service's (tests/deploy validates the manifest itself)."""
    block = _block(MARKERS["kubectl"])
    assert subprocess.run(["bash", "-n", "-c", block]).returncode == 0
    assert (ROOT / "deploy" / "k8s" / "prismcloud.yaml").is_file()
    from prism_common.settings import Settings

    for name in re.findall(r"--from-literal=PRISM_(\w+)=", block):
        assert name.lower() in Settings.model_fields, name


def test_compose_block_is_checked_not_run():
    """No Docker engine here: the block parses, it sets every variable docker-compose.yml
    requires, and the service it scales is there."""
    block = _block(MARKERS["compose"])
    assert subprocess.run(["bash", "-n", "-c", block]).returncode == 0
    compose = (ROOT / "docker-compose.yml").read_text()
    required = set(re.findall(r"\$\{(\w+):\?", compose))
    exported = set(re.findall(r"\b(\w+)=", block.split("docker compose")[0]))
    assert required <= exported, required - exported
    for service in re.findall(r"--scale (\w+)=", block):
        assert f"\n  {service}:\n" in compose, service


def test_webhooks_blocks_deliver_a_signed_job_to_the_receiver(tmp_path: Path):
    """The how-to as a user follows it: a key made by its block, its receiver (the python block)
    on this machine, `prism serve` started by its block, a job naming the receiver; the receiver
    prints the job's id and state. The receiver's port 8080 is made a free one."""
    from prism_cli.stack import free_port

    made = _bash(_block(MARKERS["webhook secret"]) + '\nprintf %s "$PRISM_WEBHOOK_SECRET"', cwd=tmp_path,
                 env=dict(os.environ), timeout=60)
    assert made.returncode == 0 and made.stdout.startswith("whsec_"), made.stdout + made.stderr
    import base64

    assert len(base64.b64decode(made.stdout.removeprefix("whsec_"))) == 32
    receiver_port, api_port = free_port(), free_port()
    env = {**os.environ, "PRISM_WEBHOOK_SECRET": made.stdout, "PRISM_SERVE_PORT": str(api_port),
           "PRISM_SERVE_DATA_DIR": str(tmp_path / ".prism"), "COLUMNS": "300"}
    env.pop("PRISM_API_KEYS", None)
    script = tmp_path / "receiver.py"
    script.write_text(python_block("standardwebhooks").replace("8080", str(receiver_port)))
    received = (tmp_path / "received.out").open("w")
    receiver = subprocess.Popen([str(ROOT / ".venv" / "bin" / "python"), str(script)], env=env,
                                stdout=received, stderr=subprocess.STDOUT, start_new_session=True)
    serve, api_port = _serve_ready(["bash", "-euo", "pipefail", "-c", _block(MARKERS["webhooks serve"])],
                                   env, tmp_path / "serve.out")
    try:
        key = json.loads((tmp_path / ".prism" / "credentials.json").read_text())["api_key"]
        client = {**env, "PRISM_API_URL": f"http://127.0.0.1:{api_port}", "PRISM_API_KEY": key}
        submit = _block(MARKERS["webhook submit"]).replace("8080", str(receiver_port))
        run = _bash(submit, cwd=ROOT, env=client, timeout=300)
        assert run.returncode == 0, run.stdout + run.stderr
        job_id = run.stdout.split()[0]
        deadline = time.monotonic() + 60
        heard = tmp_path / "received.out"
        while f"{job_id} succeeded" not in heard.read_text():
            assert receiver.poll() is None and time.monotonic() < deadline, heard.read_text()
            time.sleep(0.3)
        assert "refused" not in heard.read_text()
    finally:
        for proc in (serve, receiver):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(60)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
        received.close()


def test_test_file_blocks_name_files_the_suite_runs():
    """`pytest tests/service/...` blocks: scripts/test runs every file under tests/ (but
    tests/cluster), so CI runs them; here only that each is such a file."""
    for block in _blocks(MARKERS["a test file"]):
        (path,) = re.findall(r"-m pytest (?:-\w+ )*(tests/\S+\.py)", block)
        assert (ROOT / path).is_file() and not path.startswith("tests/cluster"), path


def test_cluster_block_is_what_ci_runs():
    block = _block(MARKERS["cluster"])
    assert block.split("#")[0].strip() == "scripts/test-cluster"
    assert "scripts/test-cluster" in (ROOT / ".ci" / "run").read_text().splitlines()


@pytest.fixture(scope="module")
def served(tmp_path_factory) -> Iterator[dict[str, str]]:
    """The README's serve block, run as written (setup included) in the background."""
    from prism_cli.stack import free_port

    data = tmp_path_factory.mktemp("prism-serve")
    port = free_port()
    env = {**os.environ, "PRISM_SERVE_PORT": str(port), "PRISM_SERVE_DATA_DIR": str(data / ".prism"),
           "COLUMNS": "300"}
    env.pop("PRISM_API_KEYS", None)
    proc, port = _serve_ready(["bash", "-euo", "pipefail", "-c", _block(MARKERS["serve"])], env,
                              data / "serve.out")
    try:
        key = json.loads((data / ".prism" / "credentials.json").read_text())["api_key"]
        yield {"port": str(port), "key": key, "log": str(data / "serve.out")}
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def _client_env(served: dict[str, str]) -> dict[str, str]:
    return {**os.environ, "PRISM_API_URL": f"http://127.0.0.1:{served['port']}",
            "PRISM_API_KEY": served["key"]}


def _as_user(block: str, served: dict[str, str]) -> str:
    return block.replace("k-...", served["key"]).replace("127.0.0.1:8000", f"127.0.0.1:{served['port']}")


def test_serve_prints_ready_and_a_one_line_hint(served):
    out = Path(served["log"]).read_text()
    hint = [line for line in out.splitlines() if "try:" in line]
    assert len(hint) == 1 and "--wait" in hint[0], out


def test_the_try_line_runs_as_printed_from_anywhere(served, tmp_path: Path):
    """Pasted into another shell as printed: no .venv/bin on PATH, no PRISM_* set, another
    folder; the port is not the default, so the line must name PRISM_API_URL itself."""
    out = Path(served["log"]).read_text()
    line = next(line for line in out.splitlines() if "try:" in line).split("try:", 1)[1].strip()
    assert f"PRISM_API_URL=http://127.0.0.1:{served['port']}" in line and served["key"] in line, line
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "COLUMNS": "300"}
    run = _bash(line, cwd=tmp_path, env=env, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert measured_within_sigma(run.stdout) == 1, run.stdout


def test_client_blocks_submit_wait_and_download(served, user_dir: Path):
    for block in _blocks(MARKERS["client"]):
        run = _bash(_as_user(block, served), cwd=user_dir, env=_client_env(served), timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        # Every result shown holds the sample's true size within its printed ±.
        assert measured_within_sigma(run.stdout) >= 1, run.stdout
    reports = list((user_dir / "out" / "job").glob("item-0/report.json"))
    assert reports, run.stdout
    dims = json.loads(reports[0].read_text())["dimensions"]
    assert dims["unit"] == "mm" and dims["height"] == pytest.approx(80, rel=1e-3)
    assert (user_dir / "out" / "job" / "results.csv").is_file()


def test_curl_block_uploads_submits_polls_and_downloads(served, user_dir: Path):
    run = _bash(_as_user(_block(MARKERS["curl"]), served), cwd=user_dir, env=_client_env(served),
                timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    got = user_dir / "out" / "curl"
    assert run.stdout.split() == sorted(p.name for p in got.iterdir()), run.stdout
    assert run.stdout.split() == ["cloud.csv", "cloud.ply", "overlay.jpg", "preview.ply", "report.json",
                                  "results.csv"], run.stdout
    dims = json.loads((got / "report.json").read_text())["dimensions"]
    assert dims["unit"] == "mm" and dims["width"] == pytest.approx(120, rel=1e-6)
    header = (got / "results.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "job_id" and set(header) == _table_fields(OUTPUTS, "results.csv"), header


def test_the_guide_is_served_at_guide_and_linked_from_the_page(served):
    if not (SITE / "index.html").is_file():
        subprocess.run(["scripts/docs"], cwd=ROOT, check=True, capture_output=True, timeout=300)
    base = f"http://127.0.0.1:{served['port']}"
    with urllib.request.urlopen(f"{base}/guide/", timeout=30) as answer:
        assert answer.status == 200 and "PrismCloud" in answer.read().decode()
        assert "default-src 'self'" in answer.headers["Content-Security-Policy"]
    with urllib.request.urlopen(f"{base}/guide/tutorials/first-job/", timeout=30) as answer:
        assert "First job over HTTP" in answer.read().decode()
    with urllib.request.urlopen(f"{base}/app/", timeout=30) as answer:
        assert 'href="../guide/"' in answer.read().decode()


def test_serve_refuses_a_taken_port_in_one_line(served):
    run = subprocess.run([str(ROOT / ".venv" / "bin" / "prism"), "serve", "--port", served["port"]],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert run.returncode == 2
    assert run.stderr.strip().count("\n") == 0 and "taken" in run.stderr, run.stderr
    assert "ready" not in run.stdout


def test_station_service_blocks_store_a_station_and_measure_its_photos(served, user_dir: Path):
    """The station how-to's service blocks, run as written against `prism serve`: the station.json
    (calibrated from `prism sample --station`'s photos, as its step 1 does) stored and listed,
    then the sample's parts submitted as one job with nothing else given, each part measured within
    max(2 %, 1.5 mm) of its true size (true_sizes.csv)."""
    from prism_cli.client import ApiClient

    s = "station-sample"
    made = _bash(f".venv/bin/prism sample --station {s}/ && .venv/bin/prism station calibrate --board "
                 f"{s}/board.json --plane {s}/plane.jpg {s}/calib/*.jpg --plate {s}/empty.jpg "
                 "--out station.json", cwd=user_dir, env=dict(os.environ), timeout=600)
    assert made.returncode == 0, made.stdout + made.stderr
    truth = _true_sizes(user_dir / "station-sample")
    parts = sorted(name for name in truth if name.startswith("parts/"))
    env = _client_env(served)
    upload = _block(MARKERS["station upload"])
    run = _bash(_as_user(upload + '\necho "ID=$ID"', served), cwd=user_dir, env=env, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    station_id = run.stdout.split("ID=")[-1].strip()
    assert re.fullmatch(r"[0-9a-f]{32}", station_id), run.stdout
    assert any(station_id in line and "line 1" in line for line in run.stdout.splitlines()), run.stdout
    run = _bash(_as_user(_block(MARKERS["station submit"]), served), cwd=user_dir,
                env={**env, "ID": station_id}, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    with ApiClient(env["PRISM_API_URL"], served["key"]) as client:
        job = client.job(run.stdout.split()[0])
    assert [item.state for item in job.items] == ["succeeded"] * len(parts) == ["succeeded"] * 6, job
    for item, part in zip(job.items, parts, strict=True):
        assert item.result is not None
        dims = item.result.dimensions.model_dump()
        for key, true in truth[part].items():
            assert abs(dims[key] - true) <= max(0.02 * true, 1.5), (part, key, dims, truth[part])


def test_certify_station_blocks_verify_flag_a_moved_camera_and_verify_on_the_service(served, user_dir: Path):
    """"Certify a station", each block run as written, in order, against `prism serve` for the last:
    the sample calibrated and its capability shown as the page shows it; the reference verified
    (its summary table as shown); a part's measurement stating "verified on", and moved.jpg
    "verified before the camera moved", warned; the station verified on the service (--remote),
    its history there."""
    from prism_cli.client import ApiClient

    page = ROOT / "docs" / "how-to" / "certify-station.md"
    shown = [b for p, b in blocks("text") if p == page]
    undated = re.compile(r"\d{4}-\d\d-\d\d")
    env = {**_client_env(served), "COLUMNS": "300"}
    runs = []
    for block in _blocks(MARKERS["certify"]):
        run = _bash(_as_user(block, served), cwd=user_dir, env=env, timeout=600)
        assert run.returncode == 0, block + run.stdout + run.stderr
        runs.append({undated.sub("DATE", line) for line in run.stdout.splitlines()})
    assert len(runs) == 4 and len(shown) == 4, (len(runs), len(shown))
    # each text block's lines, as printed by the block before it (the two scans' outputs both follow
    # the third block)
    for printed, text in zip([runs[0], runs[1], runs[2], runs[2]], shown, strict=True):
        for line in text.splitlines():
            assert undated.sub("DATE", line) in printed, (line, printed)
    assert "verification: not verified" in runs[0]
    report = json.loads((user_dir / "out" / "line1-moved" / "report.json").read_text())
    assert report["station"]["verification"]["status"] == "verified before the camera moved"
    assert report["station"]["drift"]["moved"] is True and 9 <= report["station"]["drift"]["shift_px"] <= 11
    assert json.loads((user_dir / "out" / "line1-part" / "report.json").read_text()
                      )["station"]["verification"]["status"] == "verified"
    remote = "\n".join(sorted(runs[3]))
    assert "verified on DATE with a 70 x 45 x 30 mm reference" in remote and "stored with station" in remote
    with ApiClient(env["PRISM_API_URL"], served["key"]) as client:
        station = next(s for s in client.stations() if s.name == "line 1" and s.verification
                       and s.verification.status == "verified")
        assert [v.verified for v in client.station_verifications(station.id)] == [True]


def test_mistakes_block_refuses_a_text_file_and_a_point_outside_in_one_line_each(served, user_dir: Path):
    run = _bash(_as_user(_block(MARKERS["mistakes"]), served), cwd=user_dir, env=_client_env(served),
                timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.count("refused (exit 2)") == 2, run.stdout
    errors = [line for line in run.stderr.splitlines() if line.startswith("prism: error:")]
    assert len(errors) == 2 and len(run.stderr.strip().splitlines()) == 2, run.stderr
    assert "HTTP 415" in errors[0] and "'README.md' is text" in errors[0], errors
    assert "HTTP 422" in errors[1] and "p5" in errors[1] and "outside" in errors[1], errors


def test_serve_restarted_keeps_download_links_working_and_says_stopped(tmp_path: Path):
    """Ctrl-C prints one 'stopped' line; started again on the same data, the object store is on
    the same port, so a download link handed out before the restart still works."""
    from prism_cli.stack import free_port

    port = free_port()
    env = {**os.environ, "PRISM_SERVE_PORT": str(port), "PRISM_SERVE_DATA_DIR": str(tmp_path / ".prism")}
    env.pop("PRISM_API_KEYS", None)
    prism = str(ROOT / ".venv" / "bin" / "prism")

    def start() -> tuple[subprocess.Popen, Path]:
        nonlocal port
        log = tmp_path / f"serve-{time.monotonic_ns()}.out"
        proc, port = _serve_ready([prism, "serve"], env, log, timeout=120)
        return proc, log

    def stop(proc: subprocess.Popen, log: Path) -> str:
        os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(60) == 0
        return log.read_text()

    proc, log = start()
    key = json.loads((tmp_path / ".prism" / "credentials.json").read_text())["api_key"]
    client = {**os.environ, "PRISM_API_URL": f"http://127.0.0.1:{port}", "PRISM_API_KEY": key}
    run = subprocess.run([prism, "submit", str(ROOT / "samples" / "box.jpg"), "--points",
                          "395,293 943,331 919,761 943,331 1035,298", "--width-mm", "120", "--wait"],
                         env=client, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    job_id = run.stdout.split()[0]
    status = subprocess.run([prism, "status", job_id, "--json"], env=client, capture_output=True,
                            text=True, timeout=60)
    link = json.loads(status.stdout)["items"][0]["downloads"]["report"]
    out = stop(proc, log)
    assert out.strip().splitlines()[-1] == "stopped" and out.count("stopped") == 1, out
    proc, log = start()
    try:
        with urllib.request.urlopen(link, timeout=30) as answer:  # signed before the restart
            assert json.loads(answer.read())["dimensions"]["unit"] == "mm"
    finally:
        stop(proc, log)


def test_python_client_block_measures_the_sample(served, user_dir: Path):
    script = user_dir / "client_example.py"
    script.write_text(python_block("from prism_cli.client import ApiClient"))
    run = subprocess.run([str(ROOT / ".venv" / "bin" / "python"), str(script)], cwd=user_dir,
                         env=_client_env(served), capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "succeeded 100" in run.stdout and "fitted" in run.stdout, run.stdout
    report = json.loads((user_dir / "out" / "client" / "item-0" / "report.json").read_text())
    assert report["camera"]["focal_source"] == "fitted"
    assert (user_dir / "out" / "client" / "item-0" / "overlay.jpg").stat().st_size > 0
