"""Table I shapes: CONV_XF, G and D for tactile images and flat features."""

import pytest
import torch

from app.framework.classifiers import FullyConnectedClassifier
from app.framework.discriminator import build_discriminator
from app.framework.encoder import ConvFeatureExtractor, MLPFeatureExtractor, build_encoder
from app.framework.generator import build_generator


def test_conv_encoder_gives_the_papers_feature_space_for_32x30():
    enc = build_encoder((32, 30))
    assert isinstance(enc, ConvFeatureExtractor)
    assert enc.feature_shape == (256, 6)
    out = enc(torch.randn(5, 32, 30))
    assert out.shape == (5, 256 * 6)
    assert (out >= 0).all()  # ReLU output
    convs = [m for m in enc.modules() if isinstance(m, torch.nn.Conv1d)]
    assert [c.out_channels for c in convs] == [96, 256]
    assert [c.groups for c in convs] == [32, 32]
    assert [c.stride for c in convs] == [(2,), (2,)]


@pytest.mark.parametrize("shape", [(12, 40), (7, 25), (64, 30)])
def test_conv_encoder_adapts_to_other_input_shapes(shape):
    enc = build_encoder(shape)
    assert enc(torch.randn(3, *shape)).shape == (3, enc.feature_dim)


def test_mlp_encoder_for_flat_features():
    enc = build_encoder((188,))
    assert isinstance(enc, MLPFeatureExtractor)
    assert enc(torch.randn(4, 188)).shape == (4, 128)


def test_too_short_time_axis_is_rejected():
    with pytest.raises(ValueError, match="too short"):
        build_encoder((32, 4))


@pytest.mark.parametrize("input_shape", [(32, 30), (16, 50), (188,)])
def test_generator_output_lives_in_the_encoders_feature_space(input_shape):
    enc = build_encoder(input_shape)
    g = build_generator(19, enc.feature_shape)
    d = build_discriminator(enc.feature_shape)
    f = g(torch.rand(6, 19))
    assert f.shape == (6, enc.feature_dim)
    assert d(f).shape == (6,)
    assert FullyConnectedClassifier(enc.feature_dim, 54)(f).shape == (6, 54)


def test_generator_uses_the_papers_deconvolutions_for_256x6():
    g = build_generator(19, (256, 6))
    deconvs = [m for m in g.modules() if isinstance(m, torch.nn.ConvTranspose1d)]
    assert [(d.out_channels, d.kernel_size[0], d.stride[0]) for d in deconvs] == [
        (96, 4, 2),
        (256, 3, 1),
    ]


def test_grouped_conv_by_matmul_equals_torchs_convolution():
    from app.framework.encoder import grouped_conv1d

    torch.manual_seed(0)
    x = torch.randn(7, 32, 30)
    conv = torch.nn.Conv1d(32, 96, 3, stride=2, groups=32)
    torch.testing.assert_close(grouped_conv1d(x, conv), conv(x), rtol=1e-5, atol=1e-5)
    conv2 = torch.nn.Conv1d(96, 256, 3, stride=2, groups=32)
    h = torch.relu(conv(x))
    torch.testing.assert_close(grouped_conv1d(h, conv2), conv2(h), rtol=1e-5, atol=1e-5)
