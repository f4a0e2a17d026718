"""``vibr demo``, the quick start's command, through the CLI's main()."""

import re


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
    # measured with the defaults (grid, 256x256, gradient): 42.57 dB on the reconstructed
    # pixels (99.3 %), DSSIM 60.9, 42.28 dB on all pixels
    assert psnr[0] > 41.0 and psnr[1] > 40.8 and dssim < 85 and cover > 98.0, txt
    assert read_image(out).shape == (256, 256, 3)
    # the quick start's fly-through: a 2 s orbit, decoded back
    from vibr.io.video import read_video_info

    assert read_video_info(video)[:3] == (48, 256, 256) and f"wrote {video}" in txt


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
