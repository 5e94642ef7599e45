"""Halo stitching of the U-Nets: receptive field, window layout, parity with one pass."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.perceive import make_classifier
from dyntarget.perceive.unet import ACTIVATION_FLOATS_PER_WIDTH, Stitching, receptive_radius

NAMES = {"unet-uavsar": "uavsar", "unet-xception": "xception"}


def _untrained(name: str, width: int = 4):
    import torch

    torch.manual_seed(0)
    model = make_classifier(name, width=width)
    model.model.eval()
    model.fitted = True
    return model


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.slow
def test_receptive_radius_bounds_the_gradient_support(name):
    """The analytic radius bounds the measured one (gradient of the centre output pixel
    of a randomly initialised float64 network) and is not far above it. Max pooling
    passes gradient to one input per window, so the support is a little narrower than
    the reach of the dependency."""
    import torch

    model = _untrained(name, width=4).model.double()
    n = 320
    x = torch.rand(1, 4, n, n, dtype=torch.float64, requires_grad=True)
    model(x)[0, 1, n // 2, n // 2].backward()
    rows, cols = np.nonzero(x.grad[0].abs().sum(0).numpy())
    measured = int(max(np.abs(rows - n // 2).max(), np.abs(cols - n // 2).max()))
    radius = receptive_radius(NAMES[name])
    assert measured <= radius
    assert measured >= 0.75 * radius


def test_windows_partition_the_image_on_factor_multiples():
    st = Stitching(tile=64, factor=16, halo=128, bytes_per_pixel=1024.0, memory_mib=121.0)
    shape = (960, 704)
    seen = np.zeros(shape, int)
    windows = st.windows(shape)
    assert len(windows) > 4
    for rows, cols, kr, kc in windows:
        assert rows.start % 16 == 0 and cols.start % 16 == 0
        assert (rows.stop - rows.start) % 16 == 0 and (cols.stop - cols.start) % 16 == 0
        assert (rows.stop - rows.start) * (cols.stop - cols.start) * 1024 <= 121.0 * 2**20
        r0, c0 = rows.start + kr.start, cols.start + kc.start
        r1, c1 = rows.start + kr.stop, cols.start + kc.stop
        seen[r0:r1, c0:c1] += 1
        # a full halo on every side, unless the window already reaches the image's edge
        assert rows.start == 0 or r0 - rows.start >= 128
        assert cols.start == 0 or c0 - cols.start >= 128
        assert rows.stop == shape[0] or rows.stop - r1 >= 128
        assert cols.stop == shape[1] or cols.stop - c1 >= 128
    assert (seen == 1).all()


def test_one_window_when_the_image_fits():
    st = Stitching(tile=64, factor=8, halo=64, bytes_per_pixel=1000.0, memory_mib=1100.0)
    assert st.windows((1024, 1024)) == [(slice(0, 1024), slice(0, 1024)) * 2]
    assert st.work_units((1020, 1021)) == 1024 * 1024 / 64**2  # padded to multiples of 8


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_halo_windows_equal_one_whole_image_pass(name):
    """Several halo windows give the whole-image pass to float32 rounding; halo-
    less windows do not (so the comparison can fail). Compared on the
    logit difference: an untrained network's probabilities hardly vary."""
    model = _untrained(name, width=4)
    rng = np.random.default_rng(3)
    h, w = (301, 290) if name == "unet-uavsar" else (517, 500)  # not multiples of 16
    image = rng.uniform(0, 0.6, (4, h, w)).astype(np.float32)
    whole_st = model.set_stitching("halo", memory_mib=1e6).stitching()
    whole = whole_st.run(image, _logit(model))
    spread = float(whole.max() - whole.min())
    assert spread > 1e-3
    side = 2 * whole_st.halo + 8 * whole_st.factor
    model.set_stitching("halo", memory_mib=whole_st.bytes_per_pixel * side**2 / 2**20)
    st = model.stitching()
    assert len(st.windows(st.padded_shape(image.shape[1:]))) >= 4
    np.testing.assert_allclose(st.run(image, _logit(model)), whole, atol=1e-3 * spread, rtol=0)
    # the probabilities, through predict_proba
    proba = model.predict_proba(image)
    whole_proba = model.set_stitching("halo", memory_mib=1e6).predict_proba(image)
    np.testing.assert_allclose(proba, whole_proba, atol=1e-6, rtol=0)
    st.halo = 0  # no halo: the windows' own zero padding shows at their borders
    assert np.abs(st.run(image, _logit(model)) - whole).max() > 1e-2 * spread


def _logit(model):
    import torch

    def forward(batch):
        with torch.inference_mode():
            z = model.model(torch.from_numpy(batch))
            return (z[:, 1] - z[:, 0]).numpy()

    return forward


@pytest.mark.parametrize("name", NAMES)
def test_activation_estimate_bounds_the_counted_activations(name):
    """Every layer output of one pass, counted with forward hooks, fits the estimate."""
    import torch

    for width in (4, 16):
        model = _untrained(name, width=width).model
        total = 0

        def count(_m, _i, out):
            nonlocal total
            total += out.numel()

        hooks = [m.register_forward_hook(count) for m in model.modules() if not list(m.children())]
        with torch.inference_mode():
            model(torch.zeros(1, 4, 64, 64))
        for h in hooks:
            h.remove()
        per_px = total / 64**2
        assert per_px <= ACTIVATION_FLOATS_PER_WIDTH[NAMES[name]] * width + 8
        assert per_px >= 0.8 * ACTIVATION_FLOATS_PER_WIDTH[NAMES[name]] * width


def test_blend_stitching_is_kept_and_bad_settings_refused():
    model = make_classifier("unet-uavsar", width=2)
    assert model.stitch == "halo"
    assert model.set_stitching("blend").stitching().stitch == "blend"
    with pytest.raises(InvalidParameterError, match="stitch: expected one of halo, blend"):
        model.set_stitching("overlap")
    for bad in (0, -1, float("nan"), "lots", True):
        with pytest.raises(InvalidParameterError, match="memory_mib"):
            model.set_stitching("halo", memory_mib=bad)


@pytest.mark.parametrize("name", NAMES)
def test_channels_last_prediction_equals_the_trained_networks_own_pass(name):
    """predict_proba runs a channels-last copy; the reference is the trained network
    itself (default memory format) on the whole image, softmax computed here."""
    import torch

    model = _untrained(name, width=4)
    image = np.random.default_rng(5).uniform(0, 0.6, (4, 96, 128)).astype(np.float32)
    with torch.inference_mode():
        logits = model.model(torch.from_numpy(image[None])).double()
    expected = torch.softmax(logits, dim=1)[0, 1].numpy()
    got = model.set_stitching("halo", memory_mib=1e6).predict_proba(image)
    np.testing.assert_allclose(got, expected, atol=1e-5, rtol=0)
    assert all(p.is_contiguous() for p in model.model.parameters())  # the model is untouched


@pytest.mark.parametrize("architecture", ["uavsar", "xception"])
def test_folding_batch_norms_keeps_the_networks_function(architecture):
    """With non-trivial batch-norm statistics (a fresh network's are 0/1, which any
    folding would pass), the folded network gives the unfolded one's logits to float
    rounding and holds no batch norm any more (Xception's sit after separable and
    transposed convolutions too)."""
    import torch
    from torch import nn

    from dyntarget.perceive.networks import NETWORKS, build, fold_batch_norms

    net = build(NETWORKS[architecture], 4, seed=0).eval()
    gen = torch.Generator().manual_seed(1)
    norms = [m for m in net.modules() if isinstance(m, nn.BatchNorm2d)]
    assert len(norms) == {"uavsar": 14, "xception": 15}[architecture]
    for bn in norms:
        bn.running_mean.copy_(torch.rand(bn.num_features, generator=gen) - 0.5)
        bn.running_var.copy_(torch.rand(bn.num_features, generator=gen) + 0.5)
        bn.weight.data.copy_(torch.rand(bn.num_features, generator=gen) + 0.5)
        bn.bias.data.copy_(torch.rand(bn.num_features, generator=gen) - 0.5)
    x = torch.rand(2, 4, 48, 64, generator=gen)
    with torch.no_grad():
        expected = net(x)
        got = fold_batch_norms(net)(x)
    assert not any(isinstance(m, nn.BatchNorm2d) for m in net.modules())
    spread = float(expected.max() - expected.min())
    assert spread > 0.1
    torch.testing.assert_close(got, expected, atol=1e-5 * spread, rtol=0)
    with pytest.raises(ValueError, match="evaluation mode"):
        fold_batch_norms(build(NETWORKS[architecture], 4, seed=0))


def test_xception_inference_forward_changes_no_number():
    """prepare_inference's Xception forward (residual first, ReLUs and sums in place,
    one upsampling after each up stage's sum) against the plain forward of the same
    folded, channels-last weights: equal bit for bit, the caller's input untouched,
    and the trained network's own forward unchanged."""
    import copy

    import torch
    from torch import nn

    from dyntarget.perceive.networks import (
        XceptionUNet,
        build,
        fold_batch_norms,
        prepare_inference,
    )

    net = build(XceptionUNet, 4, seed=0).eval()
    gen = torch.Generator().manual_seed(2)
    for bn in [m for m in net.modules() if isinstance(m, nn.BatchNorm2d)]:
        bn.running_mean.copy_(torch.rand(bn.num_features, generator=gen) - 0.5)
        bn.bias.data.copy_(torch.rand(bn.num_features, generator=gen) - 0.5)
    plain = fold_batch_norms(copy.deepcopy(net)).to(memory_format=torch.channels_last)
    fast = prepare_inference(copy.deepcopy(net))
    assert fast.inference and not plain.inference and not net.inference
    assert all(m.inplace for m in fast.modules() if isinstance(m, nn.ReLU))
    x = torch.rand(2, 4, 64, 96, generator=gen).contiguous(memory_format=torch.channels_last)
    before = x.clone()
    with torch.inference_mode():
        expected, got = plain(x), fast(x)
        assert torch.equal(net(x), net(x))  # the trained network's forward is not in place
    assert float(expected.max() - expected.min()) > 0.1
    assert torch.equal(got, expected)
    assert torch.equal(x, before)
