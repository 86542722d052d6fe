"""The Radiance-physics bench: captures drawn by Radiance with the effect in the physics, diagnosed blind.

Nothing of wardjax's simulator or capture writer draws these captures: the
scene (:mod:`._scene`: the rig, a pinhole camera, ``oconv``/``rtrace``), the
cases (:mod:`._cases`: what each effect changes in the scene or the camera)
and the sensor (:mod:`._sensor`: optics, exposure, photon and read noise,
response, quantisation, PNG files and ``capture.toml``) are this package's own.
:mod:`._bench` runs ``wardjax diagnose``'s discovery on each capture and keeps
one CSV row per capture::

    python -m benchmarks.radiance_bench                       # the full bench, with a progress bar
    python -m benchmarks.radiance_bench --cases null --seeds 1 --sizes 80x60   # a small run
    python -m benchmarks.radiance_bench --summary              # the figures of the stored rows
"""
