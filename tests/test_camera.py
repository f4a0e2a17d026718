import numpy as np
import pytest

from vibr import Camera, VibrInputError


def _random_cam(seed=0):
    rng = np.random.default_rng(seed)
    K = Camera.intrinsics(120.0, 64, 48)
    return Camera.look_at(rng.normal(size=3) * 3 + [0, 0, -8], [0, 0, 0], [0, -1, 0], K, 64, 48)


def test_project_backproject_roundtrip():
    cam = _random_cam()
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 60, size=(100, 2))
    z = rng.uniform(1, 10, size=100)
    X = cam.backproject(xy, z)
    xy2, z2 = cam.project(X)
    np.testing.assert_allclose(xy2, xy, atol=1e-9)
    np.testing.assert_allclose(z2, z, atol=1e-9)


def test_centre_projects_to_principal_point_direction():
    cam = _random_cam()
    # A point on the optical axis projects to the principal point, at depth = distance.
    X = cam.centre + 5.0 * cam.optical_axis
    xy, z = cam.project(X)
    np.testing.assert_allclose(xy, cam.K[:2, 2], atol=1e-9)
    assert z == pytest.approx(5.0)


def test_scaled_keeps_pixel_centre_convention():
    cam = Camera(Camera.intrinsics(100.0, 64, 48), np.eye(3), np.zeros(3), 64, 48)
    half = cam.scaled(0.5)
    assert half.shape == (24, 32)
    # Pixel centre (0.5, 0.5) of the half-size image covers original pixels 0..1 → x = 0.5 there.
    X = cam.backproject(np.array([0.5, 0.5]), 3.0)
    xy, _ = half.project(X)
    np.testing.assert_allclose(xy, [0.0, 0.0], atol=1e-12)


def test_turned_camera_sees_the_image_turned_clockwise():
    """A point seen at pixel (u, v) by a camera is seen, by the camera turned by one quarter
    turn, where np.rot90(image, -1) puts that pixel: (H - 1 - v, u); four turns are the
    camera itself; the centre and the depth of points do not change."""
    cam = Camera(np.array([[120.0, 0, 30.2], [0, 118.0, 20.7], [0, 0, 1]]), _random_cam().R, _random_cam().t, 64, 48)
    rng = np.random.default_rng(2)
    X = cam.backproject(rng.uniform(0, 47, size=(50, 2)), rng.uniform(1, 10, size=50))
    (u, v), z = cam.project(X)[0].T, cam.project(X)[1]
    one = cam.turned(1)
    assert (one.width, one.height) == (48, 64)
    xy, z1 = one.project(X)
    np.testing.assert_allclose(xy, np.stack([47 - v, u], axis=1), atol=1e-9)
    np.testing.assert_allclose(z1, z, atol=1e-9)
    np.testing.assert_allclose(one.centre, cam.centre, atol=1e-12)
    img = rng.uniform(size=(48, 64))
    turned = np.rot90(img, -1)
    assert turned.shape == one.shape and turned[33, 47 - 20] == img[20, 33]  # pixel (u, v) = (33, 20) -> (27, 33)
    assert cam.turned(4).allclose(cam) and cam.turned(2).turned(2).allclose(cam, atol=1e-9)
    assert cam.turned(3).turned(1).allclose(cam, atol=1e-9) and cam.turned(-1).allclose(cam.turned(3))
    with pytest.raises(VibrInputError, match="skewed"):
        Camera(np.array([[120.0, 0.5, 30], [0, 118.0, 20], [0, 0, 1]]), cam.R, cam.t, 64, 48).turned(1)


def test_bad_rotation_is_rejected():
    R = np.eye(3)
    R[0, 1] = 0.1
    with pytest.raises(VibrInputError, match="not a rotation"):
        Camera(Camera.intrinsics(100, 10, 10), R, np.zeros(3), 10, 10, source="cam.txt")


def test_reflection_is_rejected():
    with pytest.raises(VibrInputError, match="not a rotation"):
        Camera(Camera.intrinsics(100, 10, 10), np.diag([1.0, 1.0, -1.0]), np.zeros(3), 10, 10)


@pytest.mark.parametrize("bad", [64.5, True, "64", float("nan"), None])
def test_image_size_must_be_an_integer(bad):
    """A camera file's width of 64.5 was truncated to 64, true read as 1 and "64" as 64."""
    K = Camera.intrinsics(50.0, 64, 48)
    with pytest.raises(VibrInputError, match="width must be an integer number of pixels"):
        Camera(K, np.eye(3), np.zeros(3), bad, 48)
    assert Camera(K, np.eye(3), np.zeros(3), 64.0, np.int64(48)).shape == (48, 64)


# ----------------------------------------------------------------------------- View's checks
def _view(**kw):
    from vibr import View

    cam = Camera(Camera.intrinsics(20.0, 16, 12), np.eye(3), np.zeros(3), 16, 12)
    return View("v", kw.pop("image", np.full((12, 16, 3), 0.5, np.float32)), cam, **kw)


@pytest.mark.parametrize("image,msg", [
    (np.full((12, 16, 3), np.nan, np.float32), "found nan"),
    (np.full((12, 16, 3), 200.0), "divide by 255"),
    (np.full((12, 16, 3), -0.5), "must lie in \\[0, 1\\]"),
    (np.full((12, 16, 3), 3, np.int32), "got int32"),
])
def test_a_view_refuses_images_it_would_render_as_nonsense(image, msg):
    """An 8-bit image passed as floats rendered at 3 dB without a word; NaN failed in SSIM."""
    with pytest.raises(VibrInputError, match=msg):
        _view(image=image)


def test_a_view_scales_unsigned_integer_images_as_scikit_image():
    assert _view(image=np.full((12, 16, 3), 255, np.uint8)).image.max() == 1.0
    v = _view(image=np.full((12, 16, 3), 65535 // 5, np.uint16))
    assert v.image.dtype == np.float32 and abs(v.image[0, 0, 0] - 0.2) < 1e-6


@pytest.mark.parametrize("sz", [-1.0, float("inf"), float("nan"), np.full((12, 16), -0.1), np.full((12, 16), np.inf)])
def test_a_view_refuses_negative_or_infinite_sigma_z(sz):
    """(-1 and inf were accepted and rendered as if 0.)"""
    with pytest.raises(VibrInputError, match="sigma_z"):
        _view(sigma_z=sz)
    assert _view(sigma_z=0.0).sigma_z == 0.0
    assert np.isnan(_view(sigma_z=np.full((12, 16), np.nan)).sigma_z).all()


def test_sees_is_in_front_and_within_the_image():
    """``Camera.sees``: the image spans [−½, W − ½] × [−½, H − ½] (pixel centres at
    integers), points behind the camera are not seen."""
    import numpy as np

    from vibr.camera import Camera

    cam = Camera.from_centre(Camera.intrinsics(10.0, 4, 3), np.eye(3), np.zeros(3), 4, 3)
    # pixel (x, y) at depth 10 is X = ((x − 1.5), (y − 1), 10) with f = 10
    pts = np.array([[-2.0, 0, 10], [-2.01, 0, 10], [2.0, 0, 10], [2.01, 0, 10], [0, 1.5, 10], [0, 1.51, 10],
                    [0, 0, -10]])
    xy, z, inside = cam.sees(pts)
    assert inside.tolist() == [True, False, True, False, True, False, False]
    assert np.allclose(xy[0], [-0.5, 1.0]) and z[-1] == -10
