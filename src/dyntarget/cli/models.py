"""Classifier models: ``classifiers`` (list), ``train``, ``export-onnx``."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, load_labelled, log, plain_text, writes


def cmd_classifiers(args: argparse.Namespace) -> int:
    from dyntarget.perceive import CLASSIFIERS

    for name in CLASSIFIERS.available():
        print(f"{name:20s} {plain_text(CLASSIFIERS.get(name).summary)}")
    return EXIT_OK


def _training_scenes(args: argparse.Namespace) -> list:
    """The labelled WFOV scenes to train on: a scene directory, or one image in plan's forms."""
    from dyntarget.errors import InvalidParameterError, InvalidSceneError
    from dyntarget.io.sensors import read_any

    sensor = dict(bands=args.bands, preset=args.preset, scale=args.scale, offset=args.offset)
    if args.image:
        if args.data:
            raise InvalidParameterError("give --data DIR or IMAGE... --mask MASK, not both")
        if not args.mask:
            raise InvalidParameterError(
                "training on an image needs its label: --mask MASK (.tif, non-zero = plume, "
                "or .geojson)"
            )
        return [read_any(args.image, label=args.mask, factor=args.factor, **sensor)]
    if not args.data:
        raise InvalidParameterError(
            "give --data DIR (a scene directory with labels) or IMAGE... --mask MASK"
        )
    if args.mask:
        raise InvalidParameterError(
            "--mask labels an IMAGE; a scene directory's labels are <id>_mask.tif or <id>.geojson"
        )
    if args.bands is None and args.preset is None and args.offset is None:
        try:
            from dyntarget.io import read_scene_dir

            scenes = read_scene_dir(args.data, scale=args.scale, require_labels=True)
        except InvalidSceneError as exc:
            if "got 1 band(s)" not in str(exc):
                raise
            first = str(exc).split("; one file per band?")[0]
            raise InvalidSceneError(
                f"{first}; one file per band? train on the four as one scene: dyntarget train red.tif green.tif blue.tif "
                "nir.tif --mask LABEL.tif --preset landsat8 --classifier NAME --out MODEL"
            ) from None
        return [s.to_wfov(args.factor) for s in scenes]
    from dyntarget.io.scenes import _find_label, scene_ids

    scenes = []
    for i in scene_ids(args.data):
        path = Path(args.data) / f"{i}.tif"
        label = _find_label(path)
        if label is None:
            raise InvalidSceneError(f"{path}: no label (<id>_mask.tif or <id>.geojson)")
        scenes.append(read_any([path], label=label, factor=args.factor, **sensor))
    if not scenes:
        raise InvalidSceneError(f"{args.data}: no scenes (<id>.tif files) found")
    return scenes


@writes(model_dirs=("out",))
def cmd_train(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.crossval import classifier_kwargs
    from dyntarget.perceive import make_classifier

    scenes = _training_scenes(args)
    model = make_classifier(
        args.classifier, **classifier_kwargs(args.classifier, seed=args.seed, epochs=args.epochs)
    )
    t0 = time.perf_counter()
    model.fit(scenes)
    gsds = {s.gsd for s in scenes}  # recorded so that plan/fly notice another resolution
    model.training |= {"factor": args.factor, "wfov_gsd_m": gsds.pop() if len(gsds) == 1 else None}
    path = model.save(args.out)
    log(f"trained {args.classifier} on {len(scenes)} scenes in {time.perf_counter() - t0:.1f} s")
    print(path)
    return EXIT_OK


def _build_forest_kernels(model: Path, targets: list[str], *, default: bool) -> None:
    """The forest kernel for each target into ``model`` (``--targets``; ``default``: auto)."""
    from dyntarget.perceive import compiled

    if not (model / "forest.npz").is_file():
        if targets and not default:
            from dyntarget.errors import InvalidParameterError

            raise InvalidParameterError(
                "--targets: this forest has no packed form (beyond the kernel), nothing to build"
            )
        return
    print(model / "forest.npz")  # the packed forest, for the forest kernel
    if (model / "forest.onnx").is_file():
        print(model / "forest.onnx")  # the same forest for ONNX Runtime, where no kernel runs
    failed: list[str] = []
    kernels = compiled.build_kernels(model, targets, failed=failed if default else None)
    print(compiled.write_manifest(model, kernels=kernels))
    for k in kernels:
        log(f"random-forest: forest kernel for {k['target']} ({k['isa']}): {k['file']}")
        print(model / k["file"])
    left = [*compiled.available_targets()[1], *failed] if default else []
    if left:
        log(
            f"random-forest: no forest kernel for {'; '.join(left)}; on such a CPU --onnx "
            "runs ONNX Runtime's slower tree ensemble (docs/performance.md)"
        )


def cmd_export_onnx(args: argparse.Namespace) -> int:
    from dyntarget.io.outputs import OutputPathError
    from dyntarget.perceive import compiled, load_classifier
    from dyntarget.perceive.onnx_export import export_checked
    from dyntarget.synth import generate_scene

    native = load_classifier(args.model)  # a model directory of ours: model.onnx may be replaced
    default = args.targets.strip().lower() == "auto"  # every class this machine can build
    targets = compiled.parse_targets(args.targets)
    if default and native.name != "random-forest":
        targets = []
    if targets and native.name != "random-forest":
        from dyntarget.errors import InvalidParameterError

        raise InvalidParameterError(
            f"--targets builds the random-forest kernel; {args.model} holds a {native.name}"
        )
    for target in targets:  # every compiler before anything is written
        if compiled.target_compiler(target) is None:
            compiled.build_target(target, Path(args.model) / "unused")  # raises, one line
    # everything checked before anything is deleted: a refusal leaves the model as it was
    check = generate_scene(args.seed, 0, size=args.check_size)[0].image
    for name in ("model.onnx", "forest.npz", "forest.json", "forest.onnx"):  # a forest's too
        out = Path(args.model) / name
        if out.is_symlink() or (out.exists() and not out.is_file()):
            raise OutputPathError(f"{out}: not a regular file; it is left as it is")
    if native.name == "random-forest":
        native.estimator  # type: ignore[attr-defined]  # noqa: B018 (read model.skops first)
        compiled.check_manifest_readable(args.model)  # never rewrite what could not be read
        for old in compiled.kernel_files(args.model):  # built for the forest.npz replaced now
            old.unlink()
        if (Path(args.model) / compiled.FOREST_FILE).is_file():
            compiled.write_manifest(args.model, kernels=[])
    path, diff = export_checked(native, args.model, check)
    log(f"{native.name}: ONNX and native plume probabilities agree to {diff:.1e} on a check scene")
    print(path)
    if native.name == "random-forest":
        _build_forest_kernels(Path(args.model), targets, default=default)
    if args.int8:
        import numpy as np

        from dyntarget.perceive.int8 import quantize_int8
        from dyntarget.perceive.onnx import load_onnx

        if args.calibration:
            images = [s.to_wfov(args.factor).image for s in load_labelled(args.calibration)]
            where = f"{len(images)} scenes of {args.calibration}"
        else:
            images = [generate_scene(args.seed + 1, i, size=256)[0].image for i in range(4)]
            where = "4 synthetic 256 px scenes (give --calibration for the training scenes)"
        from dyntarget.errors import ExportError
        from dyntarget.perceive import int8 as int8_module

        path = quantize_int8(args.model, images, seed=args.seed)
        try:
            diff8 = float(
                np.abs(
                    load_onnx(args.model, int8=True).predict_proba(check)
                    - load_onnx(args.model).predict_proba(check)
                ).max()
            )
        except BaseException:
            path.unlink(missing_ok=True)
            raise
        tolerance = int8_module.INT8_TOLERANCE
        if not diff8 <= tolerance and not args.force:
            path.unlink(missing_ok=True)
            raise ExportError(
                f"{native.name}: INT8 differs from FP32 by {diff8:.1e} on the check scene, more "
                f"than the tolerance {tolerance:g}; {path.name} not kept (--force keeps it; "
                "CPUs without VNNI quantize less precisely)"
            )
        log(f"{native.name}: INT8 calibrated on {where}; differs from FP32 by {diff8:.1e} at most")
        if not diff8 <= tolerance:
            log(f"warning: above the tolerance {tolerance:g}, kept because of --force")
        print(path)
    return EXIT_OK


def cmd_install_kernel(args: argparse.Namespace) -> int:
    from dyntarget.perceive import compiled

    path = compiled.install_kernel(args.library, target=args.target)
    log(f"installed {args.library} into this user's forest-kernel cache")
    print(path)
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser("classifiers", help="list the plume classifiers")
    p.set_defaults(func=cmd_classifiers)

    p = sub.add_parser(
        "train",
        help="train a classifier on a scene directory, or on one labelled image, and save the model",
        description="Train on a scene directory (--data DIR: <id>.tif with <id>_mask.tif or "
        "<id>.geojson labels), or on one image in any form 'plan' reads (a 4-band GeoTIFF, a "
        "multi-band product with --preset/--bands, a .npz, or four band files R G B NIR) with "
        "its label --mask. Example: dyntarget train red.tif green.tif blue.tif nir.tif --mask "
        "gt.tif --preset landsat8 --classifier random-forest --out models/rf",
    )
    p.add_argument(
        "image",
        nargs="*",
        help="one labelled image instead of --data: a 4-band GeoTIFF, a multi-band product with "
        "--preset/--bands, a .npz, or four single-band files in the order R G B NIR",
    )
    o.DATA.add(p, required=False)
    o.MASK.add(p, help="the image's label (.tif, non-zero = plume, or .geojson); with IMAGE")
    o.add_sensor_options(p)
    o.CLASSIFIER.add(p, required=True)
    o.OUT.add(p, help="model directory to write")
    o.EPOCHS.add(p, default=50, help="U-Net epochs (default 50, as the paper)")
    o.FACTOR.add(p)
    o.SEED.add(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser(
        "export-onnx", help="export a trained model to ONNX (model.onnx beside it), checked"
    )
    p.add_argument("model", help="trained model directory (from 'dyntarget train')")
    p.add_argument(
        "--check-size",
        type=o.int_range(16, 4096, "a check scene size in px"),
        default=128,
        help="check scene size (default 128)",
    )
    o.SEED.add(p, help="seed of the check scene (default 0)")
    o.INT8.add(p, help="also write model.int8.onnx: static INT8 quantization (U-Nets and MLP)")
    o.FORCE.add(
        p, help="keep model.int8.onnx even when it differs from FP32 by more than the tolerance"
    )
    p.add_argument(
        "--calibration",
        help="labelled scene directory to calibrate INT8 on (the training scenes; default: "
        "synthetic scenes)",
    )
    o.FACTOR.add(p, default=4)
    p.add_argument(
        "--targets",
        default="auto",
        help="random forest: the CPUs to build the forest kernel for ahead of time, "
        "comma-separated: x86-64-v4 (AVX-512), x86-64-v3 (AVX2), x86-64, aarch64 (NEON), "
        "host (this machine's best); 'none' builds none. Default 'auto': every one of these "
        "there is a compiler for here (those left out are said on stderr). aarch64 on x86 "
        "needs aarch64-linux-gnu-gcc (Debian gcc-aarch64-linux-gnu). The libraries go into "
        "the model directory (recorded by SHA-256 in forest.json) to be installed with "
        "'dyntarget install-kernel' on the machine that runs the model; a kernel is never "
        "loaded from a model directory",
    )
    p.set_defaults(func=cmd_export_onnx)

    p = sub.add_parser(
        "install-kernel",
        help="install a forest kernel built elsewhere (export-onnx --targets) into this user's "
        "cache, the only place a kernel is loaded from (docs/reliability.md)",
    )
    p.add_argument("library", help="the library, e.g. MODEL/forest-kernel-aarch64.so")
    p.add_argument(
        "--target",
        help="x86-64-v4, x86-64-v3, x86-64 or aarch64 (default: from the file name)",
    )
    p.set_defaults(func=cmd_install_kernel)
