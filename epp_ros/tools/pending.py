"""Console scripts whose issues have not landed yet: they say so and exit with status 2.

The names are a contract (setup.py), so they exist from the start; each is replaced by its
real entry point when its issue lands.
"""
import sys

_PENDING = {
    'epp_bag': 'the "Bags" issue',
}


def _not_yet(name):
    print(f'{name}: not implemented yet; it arrives with {_PENDING[name]}.', file=sys.stderr)
    return 2


def epp_bag():
    return _not_yet('epp_bag')
