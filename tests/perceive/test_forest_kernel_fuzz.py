"""The forest kernel under AddressSanitizer and UndefinedBehaviorSanitizer.

Random packed forests that ``load_forest`` accepts (random breadth-first trees, chains
63 deep, single leaves, 1 to 8 features, garbage in the padding) are
run through both builds of ``_forest.c`` compiled with the sanitizers into a small
harness; any out-of-bounds access or undefined behaviour stops it with a report. The
probabilities must equal an independent walk of the same arrays in numpy, one level at
a time over all pixels, summed in tree order.
"""

from __future__ import annotations

import shutil
import subprocess
from importlib.resources import files

import numpy as np
import pytest

from dyntarget.perceive.compiled import PAD, load_forest

HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <stdint.h>
int dt_forest_predict(const float *, int64_t, int32_t, int32_t, int32_t, const int64_t *,
                      const float *, const int32_t *, const double *, const int32_t *,
                      int32_t, double *);
static void *take(FILE *f, size_t size) {
    void *p = malloc(size ? size : 1);  /* exact sizes: ASan sees any read past them */
    if (size && fread(p, 1, size, f) != size) exit(3);
    return p;
}
int main(int argc, char **argv) {
    for (int a = 1; a < argc; a++) {
        FILE *f = fopen(argv[a], "rb");
        int64_t h[6];
        if (!f || fread(h, 8, 6, f) != 6) return 2;
        int64_t total = h[0], trees = h[1], n = h[2], nfeat = h[3], fshift = h[4], depth = h[5];
        int64_t *node = take(f, total * 8);
        float *thr = take(f, (total + 32) * 4);
        int32_t *code = take(f, (total + 32) * 4);
        double *value = take(f, total * 8);
        int32_t *roots = take(f, trees * 4);
        float *x = take(f, n * nfeat * 4);
        fclose(f);
        double *out = malloc(n ? n * 8 : 1);
        int rc = dt_forest_predict(x, n, nfeat, fshift, depth, node, thr, code, value, roots,
                                   trees, out);
        char name[4096];
        snprintf(name, sizeof name, "%s.out", argv[a]);
        FILE *o = fopen(name, "wb");
        fwrite(&rc, 4, 1, o);
        fwrite(out, 8, n, o);
        fclose(o);
        free(node), free(thr), free(code), free(value), free(roots), free(x), free(out);
    }
    return 0;
}
"""

SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-g", "-O1"]


def _builds(tmp_path) -> dict[str, str]:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("no gcc")
    source = tmp_path / "_forest.c"
    source.write_bytes(files("dyntarget.perceive").joinpath("_forest.c").read_bytes())
    harness = tmp_path / "harness.c"
    harness.write_text(HARNESS)
    out = {}
    for name, flags in (("native", ["-march=native"]), ("portable", [])):
        exe = tmp_path / f"harness-{name}"
        done = subprocess.run(
            [gcc, *SANITIZE, *flags, "-std=c11", str(source), str(harness), "-o", str(exe)],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            pytest.skip(f"no sanitizer build here: {done.stderr.strip()[-200:]}")
        out[name] = str(exe)
    return out


def _tree(rng, start: int, nfeat: int):
    """One random tree, breadth-first with siblings adjacent: (child, feature, threshold, value)."""
    kind = rng.integers(3)
    if kind == 0:  # a single leaf
        internal = np.array([False])
    elif kind == 1:  # a chain down one side, up to 63 deep
        k = int(rng.integers(1, 64))
        internal = np.zeros(2 * k + 1, bool)
        internal[0] = True
        internal[2 * np.arange(1, k) - (rng.random() < 0.5)] = True
    else:  # random breadth-first growth
        depths, internal, i = [0], [], 0
        cap = int(rng.integers(1, 12))
        while i < len(depths):
            grow = depths[i] < cap and (depths[i] < 2 or rng.random() < 0.7)
            internal.append(grow)
            depths += [depths[i] + 1] * 2 * grow
            i += 1
        internal = np.array(internal, bool)
    size = len(internal)
    child = start + np.arange(size)
    inner = np.flatnonzero(internal)
    child[inner] = start + 1 + 2 * np.arange(len(inner))
    feature = np.where(internal, rng.integers(0, nfeat, size), 0)
    threshold = np.where(internal, rng.normal(size=size), np.inf).astype(np.float32)
    return child, feature, threshold, rng.random(size)


def _reference(child, feature, threshold, value, roots, x):
    out = np.zeros(len(x))
    rows = np.arange(len(x))
    for root in roots:
        k = np.full(len(x), root)
        while True:
            step = child[k] + (x[rows, feature[k]] > threshold[k])
            if (step == k).all():
                break
            k = step
        out += value[k]
    return out / len(roots)


def test_random_accepted_forests_run_clean_under_the_sanitizers(tmp_path):
    builds = _builds(tmp_path)
    rng = np.random.default_rng(0)
    cases, expected = [], []
    for _ in range(80):
        nfeat = int(rng.integers(1, 9))
        fshift = (nfeat - 1).bit_length()
        parts, roots, base = [], [], 0
        for _ in range(int(rng.integers(1, 8))):
            parts.append(_tree(rng, base, nfeat))
            roots.append(base)
            base += len(parts[-1][0])
        child, feature, threshold, value = (np.concatenate(p) for p in zip(*parts, strict=True))
        code = np.concatenate([(child << fshift) | feature, rng.integers(-(2**31), 2**31, PAD)])
        padded = np.concatenate([threshold, rng.normal(size=PAD) * 1e30]).astype(np.float32)
        # the true depth, from the roots down
        leaf = np.isposinf(threshold)
        level = np.full(base, -1)
        level[roots] = depth = 0
        while len(parents := np.flatnonzero((level == depth) & ~leaf)):
            depth += 1
            level[child[parents]] = level[child[parents] + 1] = depth
        assert (level >= 0).all()  # every node reached: a forest load_forest must accept
        path = tmp_path / f"forest{len(cases)}.npz"
        with open(path, "wb") as fh:
            np.savez(fh, threshold=padded, code=code.astype(np.int32), value=value,
                     roots=np.array(roots, np.int32), depth=np.int64(depth),
                     features=np.int64(nfeat), fshift=np.int64(fshift),
                     model_sha256=np.zeros(0, np.uint8))  # fmt: skip
        packed = load_forest(path)
        n = int(rng.choice([0, 1, 15, 16, 17, 1023, 1024, 1025, 2049]))
        x = rng.normal(size=(n, nfeat)).astype(np.float32)
        inner = np.flatnonzero(~leaf)[:n]
        x[np.arange(len(inner)), feature[inner]] = threshold[inner]  # pixels on thresholds
        case = tmp_path / f"case{len(cases)}.bin"
        with open(case, "wb") as fh:
            np.array([base, len(roots), n, nfeat, fshift, depth], np.int64).tofile(fh)
            for array in (packed.node, packed.threshold, packed.code, packed.value, packed.roots):
                array.tofile(fh)
            x.tofile(fh)
        cases.append(case)
        expected.append(_reference(child, feature, threshold, value, roots, x))
    for name, exe in builds.items():
        done = subprocess.run([exe, *map(str, cases)], capture_output=True, text=True)
        assert done.returncode == 0, f"{name}: {done.stderr[-2000:]}"
        for case, want in zip(cases, expected, strict=True):
            raw = np.fromfile(f"{case}.out", np.uint8)
            assert raw[:4].view(np.int32)[0] == 0
            np.testing.assert_array_equal(raw[4:].view(np.float64), want, err_msg=f"{name} {case}")
