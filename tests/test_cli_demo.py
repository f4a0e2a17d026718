"""``vibr demo``, the quick start's command, through the CLI's main()."""

import re

import pytest


@pytest.mark.slow
def test_demo_default_renders_the_held_out_view(tmp_path, capsys):
    from vibr.cli import main
    from vibr.io import read_image

    out = tmp_path / "demo.png"
    video = tmp_path / "demo.mp4"
    assert main(["demo", "-o", str(out), "--video", str(video), "-q"]) == 0
    txt = capsys.readouterr().out
    psnr = [float(x) for x in re.findall(r"PSNR\s+([\d.]+) dB", txt)]
    dssim = float(re.search(r"DSSIM\s+([\d.]+)", txt).group(1))
    cover = float(re.search(r"([\d.]+)% of the image", txt).group(1))
    # what the demo prints with the defaults (grid, 256x256, gradient, the new view halfway
    # from the centre to a corner): 41.43 dB on the reconstructed pixels (99.6 %), DSSIM 67.6,
    # 41.28 dB on all pixels; held within 1 dB
    assert psnr[0] > 40.43 and psnr[1] > 40.28 and dssim < 75 and cover > 99.0, txt
    assert read_image(out).shape == (256, 256, 3)
    # the quick start's fly-through: 3 s at 24 fps round the grid, decoded back
    from vibr.io.video import read_video_info

    assert read_video_info(video)[:3] == (72, 256, 256) and f"wrote {video}" in txt


@pytest.mark.slow
def test_demo_video_spans_the_parallax_and_keeps_the_demos_quality(tmp_path, capsys):
    """The demo's fly-through (fewer frames, the demo's size): the camera moves across the
    views, not by a few pixels (mean TV-L1 optical flow between the first frame and the
    middle one, decoded from the video, at least 5 % of the width), no frame is more than
    3 dB below the demo's own PSNR (its new view, all pixels) against the ray-cast truth at
    its camera, and the worst frame's PSNR is the one the demo prints.

    Measured at 256x256 (the demo's default, 72 frames): mean flow 6.5 % of the width, the
    demo's new view 41.28 dB (all pixels), its frames 39.34-47.06 dB (the worst 1.94 dB
    below it); here (10 frames) 39.81 dB for the worst."""
    import imageio.v3 as iio
    import numpy as np
    from skimage.color import rgb2gray
    from skimage.registration import optical_flow_tvl1

    from vibr.cli import main
    from vibr.cli.demo import demo_path
    from vibr.io import read_image
    from vibr.metrics import psnr
    from vibr.synthetic import default_world, make_scene, render_view

    video, frames, n = tmp_path / "demo.mp4", tmp_path / "frames", 10
    assert main(["demo", "--video", str(video), "--video-frames", str(n), "--frames-dir", str(frames), "-q"]) == 0
    txt = capsys.readouterr().out
    demo_psnr = float(re.search(r"PSNR\s+([\d.]+) dB\s+\(all pixels, holes", txt).group(1))
    printed = float(re.search(r"PSNR\s+([\d.]+) dB\s+\(all pixels, its worst frame", txt).group(1))
    decoded = np.stack(list(iio.imiter(video)))
    assert decoded.shape == (n, 256, 256, 3)
    v, u = optical_flow_tvl1(rgb2gray(decoded[0]), rgb2gray(decoded[n // 2]))
    assert np.hypot(u, v).mean() >= 0.05 * 256
    world = default_world(0)
    path = demo_path(make_scene(width=256, height=256), n)
    worst = min(psnr(read_image(frames / f"frame_{i:05d}.png"), render_view(world, cam, 2)[0])
                for i, cam in enumerate(path.cameras))
    assert worst >= demo_psnr - 3.0, (worst, demo_psnr)
    assert abs(printed - worst) < 0.01, (printed, worst)


def test_demo_bad_size_is_a_one_line_error(capsys):
    from vibr.cli import main

    code = main(["demo", "--size", "0", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err


def test_demo_negative_seed_is_a_one_line_error(capsys):
    """(--seed -1 was numpy's traceback.)"""
    from vibr.cli import main

    code = main(["demo", "--seed", "-1", "--no-video", "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err == "vibr demo: error: seed must be an integer >= 0 (numpy's rule), got -1"


def test_a_cold_kernel_cache_is_announced_in_one_line(monkeypatch, capsys):
    """Before the first compilation on a machine (no numba cache index for the command's
    kernels) one line says so; not with a warm cache, nor with -q."""
    import vibr.cli as cli

    probe = cli.kernels_cold("demo")
    assert isinstance(probe, bool) and cli.kernels_cold("info") is False
    for cold, quiet, shown in ((True, False, True), (False, False, False), (True, True, False)):
        monkeypatch.setattr(cli, "kernels_cold", lambda command, cold=cold: cold)
        assert cli.main(["demo", "--size", "0"] + (["-q"] if quiet else [])) == 2
        err = capsys.readouterr().err
        assert ("compiles its kernels" in err) == shown, err
        assert sum("compiles its kernels" in line for line in err.splitlines()) == int(shown)


def test_demo_never_replaces_a_file_it_did_not_write(tmp_path, capsys, monkeypatch):
    """A user's own vibr-demo.mp4 (or -o file) is refused before any work, in one line; the
    files a demo wrote are replaced by the next demo without --overwrite."""
    from vibr.cli import main

    monkeypatch.chdir(tmp_path)
    mine = tmp_path / "vibr-demo.mp4"
    mine.write_bytes(b"the user's own video")
    args = ["demo", "--size", "32", "--video-frames", "2", "-q"]
    assert main(args) == 2
    assert "vibr did not write" in capsys.readouterr().err and mine.read_bytes() == b"the user's own video"
    assert main([*args, "--overwrite", "-o", "v.png"]) == 0  # asked for
    assert mine.read_bytes() != b"the user's own video"
    assert main([*args, "-o", "v.png"]) == 0  # its own outputs: replaced without --overwrite
    (tmp_path / "u.png").write_bytes(b"not vibr's")
    assert main([*args, "--no-video", "-o", "u.png"]) == 2 and (tmp_path / "u.png").read_bytes() == b"not vibr's"
