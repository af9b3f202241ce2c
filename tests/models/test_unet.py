"""U-Net building blocks: padding to the stride, any input size, encoder/decoder shapes."""

from __future__ import annotations

import pytest
import torch

from dgse.errors import InputDataError
from dgse.models.unet import UNet, UNetArch, UNetDecoder, UNetEncoder, crop_to, make_norm, pad_to_multiple


def test_pad_to_multiple_per_channel_fill_and_crop():
    x = torch.arange(2 * 3 * 5 * 6, dtype=torch.float32).reshape(2, 3, 5, 6)
    xp, size = pad_to_multiple(x, 4, fill=(-1.0, 0.0, 1.0))
    assert xp.shape == (2, 3, 8, 8) and size == (5, 6)
    assert torch.equal(crop_to(xp, size), x)
    assert (xp[:, 0, 5:] == -1).all() and (xp[:, 0, :, 6:] == -1).all()
    assert (xp[:, 1, 5:] == 0).all() and (xp[:, 2, :, 6:] == 1).all()
    same, _ = pad_to_multiple(x[..., :4, :4], 4)
    assert same.shape == (2, 3, 4, 4)
    with pytest.raises(InputDataError):
        pad_to_multiple(x, 4, fill=(0.0, 1.0))


@pytest.mark.parametrize("shape", [(32, 32), (40, 40), (50, 30), (17, 9), (1, 1)])
def test_unet_any_size(shape):
    net = UNet(5, 3, UNetArch(base_width=4, depth=3))
    y = net(torch.randn(2, 5, *shape))
    assert y.shape == (2, 3, *shape)
    assert torch.isfinite(y).all()


def test_encoder_decoder_shapes():
    arch = UNetArch(4, 3)
    enc, dec = UNetEncoder(5, arch), UNetDecoder(2, arch)
    h, skips = enc(torch.randn(1, 5, 32, 24))
    assert h.shape == (1, 32, 4, 3)
    assert [tuple(s.shape[1:]) for s in skips] == [(4, 32, 24), (8, 16, 12), (16, 8, 6)]
    assert dec(h, skips).shape == (1, 2, 32, 24)


@pytest.mark.parametrize("norm", ["group", "batch", "none"])
@pytest.mark.parametrize("act", ["relu", "silu", "gelu", "leaky_relu"])
def test_norm_and_activation_options(norm, act):
    net = UNet(2, 1, UNetArch(base_width=3, depth=1, norm=norm, activation=act))
    assert net(torch.randn(2, 2, 6, 6)).shape == (2, 1, 6, 6)


def test_group_norm_groups_divide_channels():
    assert make_norm("group", 21, 8).num_groups == 7
    assert make_norm("group", 168, 8).num_groups == 8
    assert make_norm("group", 3, 8).num_groups == 3
    with pytest.raises(InputDataError):
        make_norm("layer", 4)  # type: ignore[arg-type]
