#!/usr/bin/env bash
# The forest's ONNX Runtime graph (dyntarget.perceive.ensemble) against scikit-learn on
# another ONNX Runtime version: the onboard extra allows onnxruntime>=1.18, the project
# is developed on the newest. Builds two forests (50 and 120 trees) and their graphs with
# this checkout, then runs the graphs in a scratch venv holding only that onnxruntime
# and numpy, and fails unless every probability equals scikit-learn's bit for bit and
# the graph's metadata names its forest.
#
#     scripts/ensemble_ort_version.sh [VERSION]      # default 1.18.0
set -euo pipefail
version="${1:-1.18.0}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
python - <<'PY'
import numpy as np
from sklearn.ensemble import RandomForestClassifier

from dyntarget.perceive.compiled import pack_forest
from dyntarget.perceive.ensemble import ensemble_graph, forest_digest

rng = np.random.default_rng(7)
x = rng.normal(size=(20000, 4)).astype(np.float32)
y = (x[:, 0] * x[:, 1] + 0.4 * rng.normal(size=20000) > 0).astype(int)
np.save("x.npy", x)
for trees in (50, 120):
    est = RandomForestClassifier(n_estimators=trees, min_samples_leaf=2, random_state=0).fit(x, y)
    packed = pack_forest(est)
    open(f"g{trees}.onnx", "wb").write(ensemble_graph(packed))
    open(f"d{trees}.txt", "w").write(forest_digest(packed))
    np.save(f"ref{trees}.npy", est.predict_proba(x)[:, 1].astype(np.float32))
PY
python -m venv venv
numpy="numpy"
case "$version" in 1.1[0-9].*) numpy="numpy<2" ;; esac  # wheels built before numpy 2
venv/bin/pip install -q "onnxruntime==$version" "$numpy"
venv/bin/python - <<'PY'
import sys

import numpy as np
import onnxruntime as ort

x, bad = np.load("x.npy"), []
for trees in (50, 120):
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    graph = open(f"g{trees}.onnx", "rb").read()
    session = ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
    named = session.get_modelmeta().custom_metadata_map.get("dyntarget_forest_sha256")
    if named != open(f"d{trees}.txt").read():
        bad.append(f"{trees} trees: the graph's metadata does not name its forest")
    ref = np.load(f"ref{trees}.npy")
    for n in (1, 100, 20000):
        out = session.run(["plume"], {"pixels": x[:n].astype(np.float64)})[0][:, 0]
        same = np.array_equal(out.astype(np.float32), ref[:n])
        print(f"onnxruntime {ort.__version__}: {trees} trees, {n} rows: "
              f"{'bit-identical' if same else 'DIFFERS'} to scikit-learn")
        if not same:
            bad.append(f"{trees} trees, {n} rows")
sys.exit("MISMATCH: " + "; ".join(bad) if bad else 0)
PY
