"""Per-pixel uncertainty of a render: metrics in closed form, σ on a synthetic
scene with exact and perturbed depth, the CLI outputs."""

import numpy as np
import pytest

from vibr.metrics import ause, pixel_error, sparsification, spearman, uncertainty_metrics


# ----------------------------------------------------------------------------- metrics
def test_perfect_predictor_has_zero_ause_and_unit_rho():
    rng = np.random.default_rng(0)
    err = rng.gamma(2.0, 3.0, (40, 50))
    for sig in (err, 3 * err + 1, np.sqrt(err)):  # any increasing function of the error
        assert ause(sig, err) == pytest.approx(0.0, abs=1e-12)
        assert spearman(sig, err) == pytest.approx(1.0)
    assert spearman(-err, err) == pytest.approx(-1.0)
    assert ause(-err, err) > 0.3  # the worst order is far from the oracle


def test_sparsification_closed_form():
    # four pixels, errors 0, 0, 3, 4 (RMSE = sqrt(25/4) = 2.5), fractions 0, ¼, ½, ¾
    err = np.array([[0.0, 0.0], [3.0, 4.0]])
    c = sparsification(err, err, n_points=4, normalise=False)
    assert c["rmse"] == pytest.approx(2.5)
    # oracle: remove 4, then 3: sqrt(25/4), sqrt(9/3), 0, 0
    assert c["oracle"] == pytest.approx([2.5, np.sqrt(3.0), 0.0, 0.0])
    assert c["curve"] == pytest.approx(c["oracle"])
    # the reversed order removes the zeros first: sqrt(25/4), sqrt(25/3), sqrt(25/2), 4
    r = sparsification(-err, err, n_points=4, normalise=False)
    assert r["curve"] == pytest.approx([2.5, np.sqrt(25 / 3), np.sqrt(12.5), 4.0])
    # normalised AUSE = mean(curve − oracle) / RMSE
    want = np.mean(np.array(r["curve"]) - np.array(r["oracle"])) / 2.5
    assert ause(-err, err, n_points=4) == pytest.approx(want)


def test_ties_are_removed_in_expectation():
    """A constant σ says nothing: its curve is the flat RMSE of a random order."""
    rng = np.random.default_rng(1)
    err = rng.random((30, 30))
    c = sparsification(np.ones_like(err), err)
    assert np.allclose(c["curve"], 1.0)
    assert np.isnan(spearman(np.ones_like(err), err))
    # inf (a pixel nobody sees) ranks as the largest σ
    sig = err.copy()
    sig[0, 0] = np.inf
    err2 = err.copy()
    err2[0, 0] = 10.0
    assert ause(sig, err2) == pytest.approx(0.0, abs=1e-12)
    assert spearman(sig, err2) == pytest.approx(1.0)


def test_uncertainty_metrics_mask_border_and_errors():
    from vibr.errors import VibrInputError

    ref = np.zeros((10, 12, 3), np.float32)
    img = ref.copy()
    img[4, 5] = 10 / 255
    e = pixel_error(img, ref)
    assert e[4, 5] == pytest.approx(10.0, rel=1e-5) and e.sum() == pytest.approx(10.0, rel=1e-5)
    m = uncertainty_metrics(e, img, ref, border=2)
    assert m["ause"] == pytest.approx(0.0, abs=1e-9) and len(m["curve"]) == 50
    with pytest.raises(VibrInputError):
        uncertainty_metrics(e[:5], img, ref)
    with pytest.raises(VibrInputError):
        sparsification(e, e, mask=np.zeros((10, 12), bool))


# ----------------------------------------------------------------------------- renderer
@pytest.fixture(scope="module")
def grid_split80():
    from vibr.synthetic import make_scene

    sc = make_scene("grid", width=80, height=80, seed=3)
    return sc.split(4)


def _noisy_depth(sources, rel, seed=0):
    """Sources whose depth maps carry Gaussian noise of std ``rel``·median depth (smoothed a
    little, as a stereo error would be), with sigma_z stating it."""
    from scipy.ndimage import gaussian_filter

    from vibr.scene import Scene

    rng = np.random.default_rng(seed)
    views = []
    for v in sources.views:
        d = np.asarray(v.depth, np.float64)
        sz = rel * float(np.nanmedian(d))
        noise = gaussian_filter(rng.standard_normal(d.shape), 1.0)
        noise *= sz / max(noise.std(), 1e-12)
        views.append(v.replace(depth=(d + noise).astype(np.float32), sigma_z=max(sz, 1e-3 * np.nanmedian(d))))
    return Scene(views, sources.name, sources.root, sources.grid, sources.points, dict(sources.meta))


def test_render_fills_uncertainty_only_when_asked(grid_split80):
    from vibr.render import render
    from vibr.render.uncertainty import hole_sigma

    src, tg = grid_split80
    r0 = render(src, tg, "bvs", max_iter=15)
    assert r0.uncertainty is None
    for method in ("gradient", "ulr"):
        r = render(src, tg, method, max_iter=15, uncertainty=True)
        s = r.uncertainty
        assert s.shape == tg.shape and s.dtype == np.float32
        assert np.all(np.isfinite(s)) and np.all(s > 0 if method != "ulr" else s >= 0)
        assert np.all(s <= hole_sigma() + 1e-3)
        if method == "ulr":  # ULR keeps the uniform rule; the default's fill term reads the neighbours
            assert np.all(s[~r.coverage] == pytest.approx(hole_sigma()))
    # the image does not depend on the flag (to the rounding of parallel sums)
    r1 = render(src, tg, "bvs", max_iter=15, uncertainty=True)
    assert np.allclose(r0.image, r1.image, atol=1e-5)


def test_sigma_grows_with_injected_depth_noise(grid_split80):
    from vibr.render import render

    src, tg = grid_split80
    med = []
    for rel in (0.0, 0.005, 0.02):
        s = src if rel == 0 else _noisy_depth(src, rel)
        r = render(s, tg, "gradient", max_iter=20, uncertainty=True)
        cov = r.coverage
        med.append((float(np.median(r.uncertainty[cov])), float(np.mean(r.uncertainty[cov]))))
    assert med[0][0] < med[1][0] < med[2][0], med
    assert med[0][1] < med[1][1] < med[2][1], med


def test_sigma_high_where_few_views_and_in_holes(grid_split80):
    """Disoccluded pixels (seen by few of the 8 sources) and push–pull pixels get a larger
    σ than pixels every source sees."""
    from vibr.geometry import compute_samples
    from vibr.geometry.samples import view_counts
    from vibr.render import render_samples
    from vibr.render.uncertainty import hole_sigma

    src, tg = grid_split80
    S = compute_samples(src, tg.camera)
    # cut a hole: drop every sample landing in a 12×12 square
    x, y = S.xy[:, 0], S.xy[:, 1]
    S = S.select(~((x > 30) & (x < 42) & (y > 30) & (y < 42)))
    n = view_counts(S)
    r = render_samples(S, "gradient", max_iter=20, uncertainty=True)
    s = r.uncertainty
    few = (n >= 1) & (n <= 3) & r.coverage
    many = n == len(src)
    assert few.sum() > 20 and many.sum() > 1000
    # measured 1.92x with the forward-difference gradient term (gamma 0.25)
    assert np.median(s[few]) > 1.5 * np.median(s[many]), (np.median(s[few]), np.median(s[many]))
    hole = np.zeros_like(r.coverage)
    hole[33:40, 33:40] = True
    assert not r.coverage[hole].any()
    # filled from textured neighbours: measured 16-24 grey levels, above the pixels every view sees
    assert np.all(s[hole] <= hole_sigma() + 1e-3) and np.median(s[hole]) > 2 * np.median(s[few]), (
        np.median(s[hole]), np.median(s[few]))


def test_sigma_ranks_the_errors_of_a_planar_proxy(grid_split80):
    """With the planar proxy the error sits where the plane is wrong; σ must find it."""
    from vibr.pipeline import prepare
    from vibr.render import render
    from vibr.synthetic import make_scene

    src, tg = prepare(make_scene("grid", width=80, height=80, seed=3), 4, depth="planar")
    r = render(src, tg, "gradient", max_iter=20, uncertainty=True)
    m = uncertainty_metrics(r.uncertainty, r.image, tg.image, border=2)
    assert m["spearman"] > 0.4 and m["ause"] < 0.2, (m["spearman"], m["ause"])


# ----------------------------------------------------------------------------- CLI
def test_sigma_scale_leaves_the_holes_out():
    """The colour scale of a σ figure spans the pixels the sources reach: holes (σ_hole, a
    third of this map, also stored as float16) would otherwise make it 0–100 and put the
    rest, 0–10, in the bottom tenth of the colours."""
    from vibr.eval.sigma_figures import sigma_scale
    from vibr.render.uncertainty import hole_sigma

    m = np.linspace(0.0, 9.9, 3000)
    m[:1000] = np.float16(hole_sigma())
    assert sigma_scale(m) == 10.0
    assert sigma_scale(np.full(10, hole_sigma())) == 100.0  # only holes: σ_hole, rounded up
    assert sigma_scale([np.nan]) == 100.0


def test_cli_render_writes_uncertainty_png_and_npy(tmp_path, capsys):
    import imageio.v3 as iio

    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    save_scene(make_scene("grid", n_views=9, width=64, height=64, seed=1), tmp_path / "s")
    for ext in ("npy", "png"):
        out = tmp_path / f"std.{ext}"
        assert main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "v.png"),
                     *(["--method", "ulr"] if ext == "png" else ["--method", "gradient", "--iterations", "10"]),
                     "--uncertainty", str(out), "-q"]) == 0
        assert out.exists()
        if ext == "npy":
            a = np.load(out)
            assert a.shape == (64, 64) and a.dtype == np.float32 and np.all(np.isfinite(a))
        else:
            a = iio.imread(out)
            assert a.ndim == 3 and a.shape[1] == 64 and a.shape[0] > 64 and a.dtype == np.uint8
    capsys.readouterr()
    bad = tmp_path / "std.tif"
    assert main(["render", str(tmp_path / "s"), "--target", "view_004", "-o", str(tmp_path / "w.png"),
                 "--uncertainty", str(bad), "-q"]) == 2
    assert not bad.exists() and not (tmp_path / "w.png").exists()
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_cli_eval_uncertainty_report_and_plot(tmp_path):
    import json

    import imageio.v3 as iio

    from vibr.cli import main
    from vibr.io import save_scene
    from vibr.synthetic import make_scene

    save_scene(make_scene("grid", n_views=9, width=64, height=64, seed=1), tmp_path / "s")
    rep = tmp_path / "r.json"
    assert main(["eval", str(tmp_path / "s"), "--target", "view_004", "--method", "ulr,gradient", "--gamma", "1",
                 "--json", str(rep), "--figures", str(tmp_path / "fig"), "--uncertainty", "-q"]) == 0
    r = json.loads(rep.read_text())
    for row in r["results"]:
        u = row["uncertainty"]
        assert 0 <= u["ause"] < 1 and -1 <= u["spearman"] <= 1 and len(u["curve"]) == len(u["oracle"])
    img = iio.imread(r["figures"]["sparsification"])
    assert img.ndim == 3 and img.shape[0] > 100
    # several targets: each view's report scores its uncertainty, the summary averages AUSE
    # (--uncertainty is not ignored with --target all or a list)
    rep2 = tmp_path / "r2.json"
    assert main(["eval", str(tmp_path / "s"), "--target", "view_000,view_004", "--method", "ulr,gradient",
                 "--gamma", "1", "--json", str(rep2), "--uncertainty", "-q"]) == 0
    r2 = json.loads(rep2.read_text())
    for lab, summ in r2["summary"].items():
        per = [row["uncertainty"]["ause"] for v in r2["per_view"].values()
               for row in v["results"] if row["label"] == lab]
        assert len(per) == 2 and summ["ause"]["mean"] == pytest.approx(sum(per) / 2)


def test_sample_statistics_one_pass_matches_separate_splats(grid_split80):
    """The one-pass kernel's splats equal the residual spread, ``(Σ w B)² / Σ w² B``
    and the weighted mean of ``sigma_z² ‖∂tau/∂z‖²`` computed by separate splats."""
    from vibr.geometry import compute_samples
    from vibr.render.operators import Splat
    from vibr.render.uncertainty import sample_statistics

    src, tg = grid_split80
    S = compute_samples(src, tg.camera)
    sp = Splat(S.xy, S.target_shape)
    rng = np.random.default_rng(0)
    w = rng.uniform(0.1, 2.0, sp.n)
    u = rng.random((3,) + S.target_shape).astype(np.float32)
    sz = rng.uniform(0.0, 0.3, sp.n)
    ws = sp.adjoint(np.ones(sp.n), w)
    st = sample_statistics(sp, w, S.colour, u, ws, sz, S.dtau_dz)
    ok = ws > 0
    assert ok.mean() > 0.9
    r = S.colour - sp.apply(u.transpose(1, 2, 0))  # colour − (B u)(m), per channel
    res = sp.adjoint((r * r).sum(1) / 3, w)
    assert np.allclose(st["s2"][ok], res[ok] / ws[ok], rtol=1e-6, atol=1e-12)
    w2 = sp.adjoint(np.ones(sp.n), w * w)
    assert np.allclose(st["n_eff"][ok], ws[ok] ** 2 / w2[ok], rtol=1e-9)
    assert np.all(st["n_eff"][~ok] == 0)
    pv = sp.adjoint(sz ** 2 * (S.dtau_dz ** 2).sum(1), w)
    assert np.allclose(st["pos_var"][ok], pv[ok] / ws[ok], rtol=1e-9)
    # without wsum the kernel accumulates Σ w B itself: the same statistics
    own = sample_statistics(sp, w, S.colour, u)
    assert np.allclose(own["s2"], st["s2"], rtol=1e-9, atol=1e-12)
    assert np.allclose(own["n_eff"], st["n_eff"], rtol=1e-9, atol=1e-12)
    # Cauchy–Schwarz: (Σ w B)² ≤ Σ w² B · Σ B, so n_eff ≤ Σ B, equal for equal weights
    nb = sp.adjoint(np.ones(sp.n))
    assert np.all(st["n_eff"][ok] <= nb[ok] * (1 + 1e-9))
    eq = sample_statistics(sp, np.ones(sp.n), S.colour, u, nb)
    assert np.all(eq["pos_var"] == 0)
    assert np.allclose(eq["n_eff"][ok], nb[ok], rtol=1e-9)


def test_hole_distance():
    from vibr.render.uncertainty import hole_distance

    cov = np.ones((9, 11), bool)
    assert np.all(np.isinf(hole_distance(cov)))
    cov[4, 5] = False
    d = hole_distance(cov)
    assert d[4, 5] == 0 and d[4, 8] == pytest.approx(3.0) and d[1, 1] == pytest.approx(5.0)


# ----------------------------------------------------------------------------- view offsets
def test_view_offsets_absorb_an_exposure_change(grid_split80):
    """``view_offsets`` is the mean residual of each view's samples; brightening one view by
    δ moves its offset by δ exactly, leaves the offset-free spread unchanged and moves the
    render's offset mix by δ times that view's share of the weight."""
    from vibr.geometry import compute_samples
    from vibr.render.operators import Splat
    from vibr.render.uncertainty import sample_statistics, view_offsets

    src, tg = grid_split80
    S = compute_samples(src, tg.camera)
    sp = Splat(S.xy, S.target_shape)
    rng = np.random.default_rng(1)
    w = rng.uniform(0.1, 2.0, sp.n)
    u = rng.random((3,) + S.target_shape).astype(np.float32)
    b, n = view_offsets(sp, S.colour, u, S.view)
    V = len(src)
    assert b.shape == (V, 3) and np.array_equal(n, np.bincount(S.view, minlength=V))
    r = S.colour - sp.apply(u.transpose(1, 2, 0))
    want = np.stack([np.bincount(S.view, r[:, c], V) for c in range(3)], 1) / n[:, None]
    assert np.allclose(b, want, rtol=1e-9, atol=1e-12)
    cen = np.array([0.01, -0.02, 0.03])
    st = sample_statistics(sp, w, S.colour, u, view=S.view, offsets=b, centre=cen)
    ws = sp.adjoint(np.ones(sp.n), w)
    ok = ws > 0
    rr = r - b[S.view]
    assert np.allclose(st["s2"][ok], (sp.adjoint((rr * rr).sum(1) / 3, w) / ws)[ok], rtol=1e-6, atol=1e-12)
    mix = sp.adjoint(b[S.view], w) / np.where(ok, ws, 1)[..., None]
    assert np.allclose(st["bias2"][ok], (((mix - cen) ** 2).sum(-1) / 3)[ok], rtol=1e-6, atol=1e-12)
    assert np.all(st["bias2"][~ok] == 0)
    plain = sample_statistics(sp, w, S.colour, u)  # the other statistics do not change
    assert np.allclose(plain["n_eff"], st["n_eff"]) and "bias2" not in plain
    delta = 0.05
    c2 = S.colour + np.where(S.view == 0, delta, 0.0)[:, None].astype(np.float32)
    b2, _ = view_offsets(sp, c2, u, S.view)
    assert np.allclose(b2[0], b[0] + delta, atol=1e-6) and np.allclose(b2[1:], b[1:], atol=1e-12)
    st2 = sample_statistics(sp, w, c2, u, view=S.view, offsets=b2, centre=cen)
    assert np.allclose(st2["s2"], st["s2"], rtol=1e-4, atol=1e-9)
    share0 = sp.adjoint(np.ones(sp.n), w * (S.view == 0)) / np.where(ok, ws, 1)
    want = (((mix + delta * share0[..., None] - cen) ** 2).sum(-1) / 3)
    assert np.allclose(st2["bias2"][ok], want[ok], rtol=1e-4, atol=1e-9)
    # stride 2: the offsets of every second sample
    bs, ns = view_offsets(sp, S.colour, u, S.view, stride=2)
    v2 = S.view[::2]
    assert np.array_equal(ns, np.bincount(v2, minlength=V))
    want2 = np.stack([np.bincount(v2, r[::2, c], V) for c in range(3)], 1) / ns[:, None]
    assert np.allclose(bs, want2, rtol=1e-9, atol=1e-12)


def test_view_offset_prior_closed_form():
    from vibr.render.uncertainty import view_offset_prior

    offs = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [-7.0, 3.0]])
    counts = np.array([10, 4, 3, 0])  # the fourth view has no sample: left out
    # median 1, MAD 1: σ_β² = 1.4826², V = 3: times 1 + π/6
    centre, var = view_offset_prior(offs, counts)
    assert np.allclose(centre, [1.0, 1.0]) and var == pytest.approx(1.4826 ** 2 * (1 + np.pi / 6))
    # an odd view moves neither the median nor the MAD much
    centre, var2 = view_offset_prior(np.r_[offs[:3], [[40.0, 40.0]]], np.array([1, 1, 1, 1]))
    assert np.allclose(centre, [1.5, 1.5]) and var2 < 2 * var
    centre, var = view_offset_prior(offs[:1], counts[:1])  # one view: no spread
    assert np.allclose(centre, [0.0, 0.0]) and var == 0


def test_sigma_follows_a_source_exposure_change(grid_split80):
    """One source exposed 1.4 times longer than the others and the target, and the only view
    left in a square: there the sources agree (one view) but the render carries its offset.
    The spread of the samples misses that error; the view-offset term predicts it."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples

    src, tg = grid_split80
    S = compute_samples(src, tg.camera)
    x, y = S.xy[:, 0], S.xy[:, 1]
    S = S.select(~((x > 20) & (x < 50) & (y > 20) & (y < 50) & (S.view != 0)))
    S.colour[:] = np.clip(S.colour * np.where(S.view == 0, 1.4, 1.0)[:, None], 0, 1)
    rho, sig = {}, {}
    for terms in ("model+spread+hole", True):
        r = render_samples(S, "gradient", max_iter=30, uncertainty=terms)
        rho[terms] = uncertainty_metrics(r.uncertainty, r.image, tg.image, border=2)["spearman"]
        sig[terms] = float(np.median(r.uncertainty[25:45, 25:45]))
    assert rho[True] > rho["model+spread+hole"], rho
    assert sig[True] > 3 * sig["model+spread+hole"], sig


def test_an_exposure_gain_leaves_black_pixels_certain(grid_split80):
    """The sources' exposures differ by a gain, which moves a black pixel by nothing: the
    ``gain`` term adds nothing where the render is black (its σ there is the σ without
    offsets), the additive ``views`` term adds its offsets there too."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples
    from vibr.render.uncertainty import TERMS

    src, tg = grid_split80
    S = compute_samples(src, tg.camera)
    S.colour[S.xy[:, 0] < 30] = 0.0  # the left of the target's frame black in every view
    S.colour[:] = S.colour * np.array([0.8, 1.0, 1.2, 1.1, 0.9, 1.0, 1.0, 1.0])[S.view % 8][:, None]
    black, bright = (slice(20, 60), slice(3, 16)), (slice(20, 60), slice(44, 76))
    med = {}
    for terms in ("model+spread+hole", "model+spread+gain+hole", "model+spread+views+hole"):
        r = render_samples(S, "gradient", max_iter=30, uncertainty=terms)
        med[terms] = (float(np.median(r.uncertainty[black])), float(np.median(r.uncertainty[bright])))
    assert "gain" in TERMS
    assert np.median(r.image[black]) < 0.005
    # measured: black 0.61 / 0.61 / 4.85 grey levels; bright 5.10 / 5.11 / 4.20
    none, gain, views = med["model+spread+hole"], med["model+spread+gain+hole"], med["model+spread+views+hole"]
    assert gain[0] < 1.2 * none[0] and views[0] > 4 * none[0], med
    assert gain[1] > 0.9 * none[1], med


def test_fill_variance_follows_what_the_hole_is_filled_from():
    """A push–pull filled pixel is known as well as the pixels it is filled from agree: amid a
    uniform backdrop, their own variance; between black and white, more than σ_hole (so the
    cap holds); covered pixels keep their variance."""
    from vibr.render.uncertainty import fill_variance, hole_sigma

    H, W = 32, 48
    cov = np.ones((H, W), bool)
    cov[12:20, 20:28] = False
    var = np.full((H, W), 4.0)
    flat = np.full((3, H, W), 0.2)
    fv = fill_variance(flat, var, cov)
    assert np.allclose(fv[cov], 4.0) and np.allclose(fv[~cov], 4.0, rtol=1e-4)
    edge = np.zeros((H, W, 3))
    edge[:, W // 2:] = 1.0
    fe = fill_variance(edge.transpose(2, 0, 1), var, cov)
    assert fe[16, 23] > hole_sigma() ** 2 and fe[16, 23] > 100 * fv[16, 23]


def test_default_sigma_of_a_hole_on_a_black_backdrop_is_small():
    """Through render(): the default terms give a hole amid black a small σ, where the former
    rule (no ``fill``) gives every filled pixel σ_hole."""
    from vibr.geometry import compute_samples
    from vibr.render import render_samples
    from vibr.render.uncertainty import hole_sigma
    from vibr.synthetic import make_scene

    src, tg = make_scene("grid", width=64, height=64, seed=1).split(4)
    src = src.replace(views=[v.replace(image=np.zeros_like(v.image)) for v in src.views])
    S = compute_samples(src, tg.camera)
    x, y = S.xy[:, 0], S.xy[:, 1]
    S = S.select(~((x > 24) & (x < 40) & (y > 24) & (y < 40)))  # a hole no sample reaches
    r = render_samples(S, "gradient", max_iter=20, uncertainty=True)
    r0 = render_samples(S, "gradient", max_iter=20, uncertainty="model+spread+gain+hole")
    hole = ~np.asarray(r.coverage, bool)
    assert hole.sum() > 50
    assert np.allclose(r0.uncertainty[hole], hole_sigma())
    assert np.median(r.uncertainty[hole]) < 3.0  # measured 1.57 grey levels
