"""Side-by-side timings of wardjax against peers; each module has a ``main()``."""
