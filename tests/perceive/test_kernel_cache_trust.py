"""The forest-kernel cache loads only what this user's dyntarget built (issue 29).

A library planted in the cache (a world-writable folder, another owner, a file whose
bytes are not the ones recorded when it was built, or a ``.so`` without the kernel's
symbols) is never ``dlopen``-ed: its constructor would run inside the process.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

from dyntarget.errors import MissingExtraError
from dyntarget.perceive import compiled

pytestmark = pytest.mark.skipif(compiled.compiler() is None, reason="needs a C compiler")

PLANTED = r"""
#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
    FILE *f = fopen(MARKER, "w"); if (f) { fputs("ran", f); fclose(f); }
}
"""


def _plant(tmp_path, target):
    """Compile a library whose constructor writes a marker file, at ``target``."""
    src, marker = tmp_path / "planted.c", tmp_path / "marker"
    src.write_text(PLANTED)
    cc = compiled.compiler().split()
    subprocess.run(
        [*cc, "-shared", "-fPIC", f'-DMARKER="{marker}"', str(src), "-o", str(target)],
        check=True,
    )
    return marker


def _built(tmp_path):
    cache = tmp_path / "cache"
    lib = compiled.build_library(cache, isa="portable")
    return cache, lib


def test_a_build_records_its_hash_and_is_private(tmp_path):
    cache, lib = _built(tmp_path)
    digest = lib.with_name(lib.name + ".sha256")
    assert digest.read_text().strip() == __import__("hashlib").sha256(lib.read_bytes()).hexdigest()
    assert os.stat(cache).st_mode & 0o077 == 0  # the folder is made for its user alone
    assert os.stat(lib).st_mode & 0o022 == 0
    assert compiled.build_library(cache, isa="portable") == lib  # found again, not rebuilt


def test_a_library_swapped_in_after_the_build_is_not_loaded(tmp_path, monkeypatch):
    cache, lib = _built(tmp_path)
    marker = _plant(tmp_path, lib)  # same name, same owner, mode 755: only the hash differs
    monkeypatch.setattr(compiled, "compiler", lambda: None)  # a flight computer: no compiler
    with pytest.raises(MissingExtraError, match="C compiler"):
        compiled.build_library(cache, isa="portable")
    assert not marker.exists()


def test_with_a_compiler_the_swapped_library_is_rebuilt_not_run(tmp_path):
    cache, lib = _built(tmp_path)
    marker = _plant(tmp_path, lib)
    again = compiled.build_library(cache, isa="portable")
    dll = compiled._load(again)
    assert dll.dt_forest_abi() == 2  # the real kernel again
    assert not marker.exists()


def test_a_cache_folder_others_can_write_is_refused(tmp_path):
    cache, _lib = _built(tmp_path)
    os.chmod(cache, 0o777)
    with pytest.raises(MissingExtraError, match="writable by others"):
        compiled.build_library(cache, isa="portable")


@pytest.mark.skipif(os.getuid() != 0, reason="changing a file's owner needs root")
def test_a_library_owned_by_another_user_is_not_loaded(tmp_path, monkeypatch):
    cache, lib = _built(tmp_path)
    os.chown(lib, 1, 1)
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    with pytest.raises(MissingExtraError, match="C compiler"):
        compiled.build_library(cache, isa="portable")


def test_a_library_without_the_kernels_symbols_is_one_clear_error(tmp_path):
    _cache, lib = _built(tmp_path)
    other = tmp_path / "other.so"
    _plant(tmp_path, other)
    shutil.copy(other, lib)
    digest = lib.with_name(lib.name + ".sha256")
    digest.write_text(__import__("hashlib").sha256(lib.read_bytes()).hexdigest())
    # even recorded as ours, a library without the symbols is refused by name, not AttributeError
    with pytest.raises(MissingExtraError, match="not a forest kernel"):
        compiled._load(lib)


def test_the_fallback_is_said_once_on_stderr(tmp_path, monkeypatch, capsys):
    import numpy as np
    from sklearn.ensemble import RandomForestClassifier

    rng = np.random.default_rng(0)
    x = rng.random((200, 4)).astype(np.float32)
    forest = RandomForestClassifier(n_estimators=3, max_depth=3, random_state=0)
    packed = compiled.pack_forest(forest.fit(x, x[:, 0] > 0.5))
    cache = tmp_path / "open"
    cache.mkdir(mode=0o777)
    os.chmod(cache, 0o777)
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path / "open-root"))
    monkeypatch.setattr(compiled, "cache_dir", lambda: cache)
    monkeypatch.delenv(compiled.ISA_ENV, raising=False)
    monkeypatch.setattr(compiled, "_SAID", set())
    assert compiled.fast_predictor(packed) is None
    assert compiled.fast_predictor(packed) is None
    err = capsys.readouterr().err
    assert err.count("forest kernel is not used") == 1
    assert "writable by others" in err
