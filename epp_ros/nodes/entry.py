"""Console scripts of the nodes: the stop request is taken before anything slow is imported.

A signal between the interpreter's start and the node's ``main`` would otherwise land in an
import and print a traceback; the node module is imported only once SIGINT and SIGTERM
merely request a shutdown (``stopping``), which ``run_node`` then honours.
"""
import importlib
import sys

from epp_ros.nodes.stopping import ShutdownRequest, ignore_signals, shutdown_on_signals


def _run(module):
    shutdown_on_signals()
    main = importlib.import_module(module).main
    if ShutdownRequest.requested:           # asked to stop while importing: nothing to do
        ignore_signals()                    # (the interpreter's exit restores the defaults)
        return 0
    return main()


def uwb_driver():
    """``uwb_driver``."""
    return _run('epp_ros.nodes.driver')


def posture_estimator():
    """``posture_estimator``."""
    return _run('epp_ros.nodes.estimator')


def uwb_emulator():
    """``uwb_emulator``."""
    return _run('epp_ros.nodes.emulator')


if __name__ == '__main__':
    sys.exit(globals()[sys.argv.pop(1)]())
