"""The runtime type checker the test suite installs over wardjax (see conftest.py).

beartype with the PEP 484 numeric tower: an ``int`` is accepted where a
``float`` is annotated and a ``float`` where a ``complex`` is, as static type
checkers read those hints.
"""

from beartype import BeartypeConf, beartype

typecheck = beartype(conf=BeartypeConf(is_pep484_tower=True))
