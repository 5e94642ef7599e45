"""The industrial smoke plume loader: converter on a fixture in the published layout, fetch on loopback."""

from __future__ import annotations

import hashlib
import http.server
import io
import json
import tarfile
import threading
import warnings
from typing import ClassVar

import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.crs import CRS

from dyntarget import DataFileError
from dyntarget.cli import main
from dyntarget.datasets import industrial_smoke as smoke
from dyntarget.io import read_scene_dir

POS = "site-a_2019-05-09T10:26:31.tif"
NEG = "site-b_2019-06-01T10:20:00.tif"


def _s2_tif(seed: int, size: int = 120) -> bytes:
    """A 13-band uint16 Sentinel-2 stack; band k holds 100 * k (+ noise) so band selection is checkable."""
    rng = np.random.default_rng(seed)
    data = np.stack(
        [(100 * k + rng.integers(0, 50, (size, size))).astype(np.uint16) for k in range(1, 14)]
    )
    buf = io.BytesIO()
    with warnings.catch_warnings(), rasterio.MemoryFile() as mem:
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with mem.open(
            driver="GTiff",
            height=size,
            width=size,
            count=13,
            dtype="uint16",
            crs=CRS.from_epsg(32633),
            transform=Affine(10, 0, 4e5, 0, -10, 5.5e6),
        ) as ds:
            ds.write(data)
        buf.write(mem.read())
    return buf.getvalue()


def _tar(path, members: dict[str, bytes]):
    with tarfile.open(path, "w:gz") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))


@pytest.fixture
def published(tmp_path):
    """The two archives, laid out exactly as the Zenodo record publishes them."""
    src = tmp_path / "download"
    src.mkdir()
    _tar(
        src / "images.tar.gz",
        {
            f"images/positive/{POS}": _s2_tif(0),
            f"images/negative/{NEG}": _s2_tif(1),
            "images/positive/unlabelled_2019-01-01T00:00:00.tif": _s2_tif(2),
        },
    )
    label = {
        "data": {"image": f"/data/upload/7-{POS.replace('.tif', '.png')}"},
        "completions": [
            {"result": [{"value": {"points": [[10, 10], [50, 10], [50, 50], [10, 50]]}}]}
        ],
    }
    _tar(
        src / "segmentation_labels.tar.gz",
        {"segmentation_labels/7.json": json.dumps(label).encode()},
    )
    return src


def test_label_image_name_rule():
    assert (
        smoke.label_image_name("/data/upload/7-x_2019-05-09T10:26:31.png")
        == "x_2019-05-09T10:26:31.tif"
    )


def test_prepare_fixture(published, tmp_path):
    out = tmp_path / "scenes"
    ids = smoke.prepare(published, out, negatives=True, progress=False)
    assert sorted(ids) == ["site-a_2019-05-09T10-26-31", "site-b_2019-06-01T10-20-00"]
    scenes = {s.id: s for s in read_scene_dir(out, require_labels=True)}
    pos = scenes["site-a_2019-05-09T10-26-31"]
    # R, G, B, NIR = B4, B3, B2, B8 of the 13-band stack, scaled by 1/10000
    np.testing.assert_allclose(
        pos.image.reshape(4, -1).min(axis=1), [0.04, 0.03, 0.02, 0.08], atol=1e-6
    )
    # polygon 10..50 % of 120 px = pixels 12..60, rasterised with all_touched
    assert pos.label[30, 30] and not pos.label[5, 5] and not pos.label[80, 80]
    rows, cols = np.nonzero(pos.label)
    assert 11 <= rows.min() <= 12 and 59 <= rows.max() <= 60 and 11 <= cols.min() <= 12
    assert pos.crs == "EPSG:32633" and pos.gsd == 10.0
    assert not scenes["site-b_2019-06-01T10-20-00"].label.any()


def test_prepare_from_extracted_folders(published, tmp_path):
    for archive in ("images.tar.gz", "segmentation_labels.tar.gz"):
        with tarfile.open(published / archive) as tar:
            tar.extractall(tmp_path / "extracted", filter="data")
    ids = smoke.prepare(tmp_path / "extracted", tmp_path / "s", progress=False)
    assert ids == ["site-a_2019-05-09T10-26-31"]


def test_prepare_errors(tmp_path, capsys):
    with pytest.raises(
        DataFileError, match="neither segmentation_labels.tar.gz nor its extracted folder"
    ):
        smoke.prepare(tmp_path, tmp_path / "out", progress=False)
    (tmp_path / "segmentation_labels.tar.gz").write_bytes(b"broken")
    code = main(
        [
            "datasets",
            "prepare",
            "industrial-smoke",
            "--from",
            str(tmp_path),
            "--out",
            str(tmp_path / "o"),
        ]
    )
    assert code == 2 and "not a readable archive" in capsys.readouterr().err


class _RangeHandler(http.server.BaseHTTPRequestHandler):
    files: ClassVar[dict[str, bytes]] = {}
    record: ClassVar[dict] = {}

    def log_message(self, *args):  # keep test output clean
        pass

    def do_GET(self):
        if self.path.startswith("/api/records"):
            body, status, extra = json.dumps(self.record).encode(), 200, {}
        else:
            data = self.files[self.path.lstrip("/")]
            start = 0
            if "Range" in self.headers:
                start = int(self.headers["Range"].split("=")[1].split("-")[0])
            body, status = data[start:], 206 if start else 200
            extra = {"Content-Range": f"bytes {start}-{len(data) - 1}/{len(data)}"} if start else {}
        self.send_response(status)
        for k, v in extra.items():
            self.send_header(k, v)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)


@pytest.fixture
def server(published):
    files = {
        name: (published / name).read_bytes()
        for name in ("images.tar.gz", "segmentation_labels.tar.gz")
    }
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _RangeHandler)
    base = f"http://127.0.0.1:{httpd.server_address[1]}"
    _RangeHandler.files = files
    _RangeHandler.record = {
        "files": [
            {
                "key": k,
                "size": len(v),
                "checksum": "md5:" + hashlib.md5(v).hexdigest(),
                "links": {"self": f"{base}/{k}"},
            }
            for k, v in files.items()
        ]
    }
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield base, files
    httpd.shutdown()
    httpd.server_close()


def test_fetch_resumes_and_verifies(server, tmp_path, capsys):
    base, files = server
    to = tmp_path / "dl"
    to.mkdir()
    half = files["images.tar.gz"][: len(files["images.tar.gz"]) // 2]
    (to / "images.tar.gz.part").write_bytes(half)  # an interrupted earlier download
    code = main(
        [
            "datasets",
            "fetch",
            "industrial-smoke",
            "--to",
            str(to),
            "--url",
            f"{base}/api/records/4250706",
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    for name, data in files.items():
        assert (to / name).read_bytes() == data
    assert not list(to.glob("*.part"))
    # and the downloaded archives prepare into scenes
    assert (
        main(
            [
                "datasets",
                "prepare",
                "industrial-smoke",
                "--from",
                str(to),
                "--out",
                str(tmp_path / "s"),
                "--quiet",
            ]
        )
        == 0
    )


def test_fetch_checksum_mismatch(server, tmp_path):
    base, _ = server
    _RangeHandler.record["files"][0]["checksum"] = "md5:" + "0" * 32
    with pytest.raises(DataFileError, match="does not match the record"):
        smoke.fetch(tmp_path, api_url=f"{base}/api/records/4250706", progress=False)
    assert not list(tmp_path.glob("*.part"))


def test_fetch_offline_fails_cleanly(tmp_path, capsys):
    # port 9 (discard) on loopback: nothing listens, the connection is refused at once
    code = main(
        [
            "datasets",
            "fetch",
            "industrial-smoke",
            "--to",
            str(tmp_path),
            "--url",
            "http://127.0.0.1:9/api/records/4250706",
            "--quiet",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert (
        "cannot download" in err and "Is the network reachable?" in err and "Traceback" not in err
    )


def test_unknown_dataset(tmp_path, capsys):
    assert main(["datasets", "fetch", "eurosat", "--to", str(tmp_path)]) == 2
    assert "unknown dataset 'eurosat'; expected one of: industrial-smoke" in capsys.readouterr().err
