"""Pose and rectification of raw photos from a printed ArUco marker board (OpenCV).

The sample lies on (or in the middle of) an ArUco grid board
(``cv2.aruco.GridBoard``: ``markers = [nx, ny]`` markers of side
``marker_size`` mm, ``separation`` mm apart; the sample may cover the central
markers, any two or more found suffice). In each photo OpenCV's
``ArucoDetector`` finds the markers and :meth:`cv2.aruco.Board.matchImagePoints`
pairs their corners with the board's; then

* the camera pose is ``cv2.solvePnP`` of those pairs (pinhole of focal length
  ``focal_px``, principal point at the image centre, no lens distortion), the
  camera centre ``C = −Rᵀ t`` in the sample frame;
* the homography ``cv2.findHomography`` from the board plane to the image
  resamples the photo onto a grid of ``pixels = [W, H]`` square pixels of side
  ``board width / W`` centred on the board (bilinear): the rectified photo
  of the sample plane, whose values are the radiance the camera saw.

Sample frame: origin at the board's centre, x to the right of the printed
board, y up it (OpenCV's board y runs down), z out of the board.
"""

from __future__ import annotations

import numpy as np

from ._errors import CaptureError

__all__ = ["board_layout", "rectify_views"]


def board_layout(board_cfg):
    """The OpenCV dictionary and GridBoard of a ``[board]`` section, and the board's width and height (mm)."""
    import cv2

    name = board_cfg.dictionary
    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        raise CaptureError("capture.toml", "board.dictionary", f"{name!r} is not an OpenCV ArUco dictionary (DICT_…)")
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    nx, ny = board_cfg.markers
    ms, sep = board_cfg.marker_size, board_cfg.separation
    board = cv2.aruco.GridBoard((nx, ny), ms, sep, dictionary)
    return dictionary, board, nx * ms + (nx - 1) * sep, ny * ms + (ny - 1) * sep


def _gray8(linear: np.ndarray) -> np.ndarray:
    g = linear.mean(axis=-1)
    return np.clip(np.rint(255.0 * np.sqrt(np.clip(g / max(float(g.max()), 1e-12), 0, 1))), 0, 255).astype(np.uint8)


def _view(shot, field: str, board_cfg, dictionary, board, bw: float, bh: float):
    """Camera centre, its axes (rows right, down, forward), and the dst→src homography of one photo."""
    import cv2

    detector = cv2.aruco.ArucoDetector(dictionary, cv2.aruco.DetectorParameters())
    corners, ids, _ = detector.detectMarkers(_gray8(shot.linear))
    found = 0 if ids is None else len(ids)
    if found < 2:
        raise CaptureError(
            shot.name,
            None,
            f"the marker board was not found ({found} {board_cfg.dictionary} markers detected, need 2); "
            f"check capture.toml [board] and that the board is in view",
        )
    obj, img = board.matchImagePoints(corners, ids)
    obj = obj.reshape(-1, 3).astype(np.float64)
    img = img.reshape(-1, 2).astype(np.float64)
    plane = np.stack([obj[:, 0] - bw / 2, bh / 2 - obj[:, 1]], -1)  # sample frame: y up, origin at the centre
    h, w = shot.shape
    f = board_cfg.focal_px
    kmat = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], np.float64)
    obj3 = np.concatenate([plane, np.zeros((len(plane), 1))], -1)
    ok, rvec, tvec = cv2.solvePnP(obj3, img, kmat, None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise CaptureError(shot.name, None, "the camera pose could not be solved from the marker board's corners")
    rot, _ = cv2.Rodrigues(rvec)
    centre = (-rot.T @ tvec).ravel()
    if centre[2] <= 0:
        raise CaptureError(shot.name, None, f"the board's pose puts the camera behind the sample (z = {centre[2]:.1f})")
    hom, _ = cv2.findHomography(plane, img, 0)
    if hom is None:
        raise CaptureError(shot.name, None, "no homography from the marker board's corners (degenerate detection)")
    return centre, rot, hom


def rectify_views(cfg, shots):
    """Rectify each raw photo onto the board-centred grid.

    Returns
    -------
    cams, lights
        ``(K, 3)`` camera centres and light positions (mm, sample frame).
    linear, step
        ``(H, W, K, C)`` rectified linear values and quantisation steps.
    clipped
        ``(H, W, K)`` clipped or outside the photo.
    width
        The rectified grid's width, mm.
    """
    import cv2

    dictionary, board, bw, bh = board_layout(cfg.board)
    wp, hp = cfg.board.pixels
    pixel = bw / wp
    to_plane = np.array([[pixel, 0, (0.5 - wp / 2) * pixel], [0, -pixel, -(0.5 - hp / 2) * pixel], [0, 0, 1]])
    cams, lights, lin, clip, step = [], [], [], [], []
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    for i, (shot, view) in enumerate(zip(shots, cfg.photos)):
        centre, rot, hom = _view(shot, f"photos[{i}]", cfg.board, dictionary, board, bw, bh)
        m = hom @ to_plane

        def warp(a, m=m):
            return cv2.warpPerspective(np.ascontiguousarray(a, np.float64), m, (wp, hp), flags=flags)

        inside = warp(np.ones(shot.shape)) > 0.999
        lin.append(warp(shot.linear))
        step.append(warp(shot.step))
        clip.append((warp(shot.clipped.astype(np.float64)) > 0) | ~inside)
        ox, oy, oz = view.light_offset or (0.0, 0.0, 0.0)
        light = np.asarray(view.light, np.float64) if view.light is not None else centre
        if view.light is None:
            light = centre + ox * rot[0] - oy * rot[1] + oz * rot[2]
        cams.append(centre)
        lights.append(light)
    return np.asarray(cams), np.asarray(lights), np.stack(lin, 2), np.stack(clip, 2), np.stack(step, 2), float(bw)
