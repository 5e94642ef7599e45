from __future__ import annotations

import rasterio

from dyntarget.cli import main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_synth_writes_76_files_byte_identical(tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    for d in (a, b):
        code, _, err = run(
            capsys, "synth", "--scenes", 38, "--size", 32, "--seed", 0, "--out", d, "--quiet"
        )
        assert code == 0, err
    files = sorted(p.name for p in a.iterdir())
    assert len(files) == 76
    for name in files:
        assert (a / name).read_bytes() == (b / name).read_bytes()
        with rasterio.open(a / name) as src:
            assert src.count in (1, 4)


def test_demo_writes_picture(tmp_path, capsys):
    code, out, err = run(capsys, "demo", "--out", tmp_path, "--scenes", 3, "--size", 48, "--quiet")
    assert code == 0, err
    assert (tmp_path / "scenes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "scenes.png" in out


def test_bad_argument_exit_2_no_traceback(tmp_path, capsys):
    code, _, err = run(capsys, "synth", "--scenes", 0, "--out", tmp_path)
    assert code == 2
    assert "positive integer" in err and "Traceback" not in err


def test_library_error_exit_2_one_line(tmp_path, capsys):
    code, _, err = run(capsys, "synth", "--scenes", 1, "--size", 4, "--out", tmp_path, "--quiet")
    assert code == 2
    assert err.strip().splitlines() == ["dyntarget: error: size: expected an integer >= 16, got 4"]
