# Copyright 2026 epp_ros developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Running an epp_ros node: start-up errors in one line, spinning, signals, clean shutdown."""
import os
from pathlib import Path
import re
import sys
import tempfile

from epp_ros.app.threads import single_blas_thread
from epp_ros.nodes.stopping import ignore_signals, shutdown_on_signals
import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.signals import SignalHandlerOptions
import yaml


#: rclpy's error type for a failed rcl call (not exported under a public name).
RCLError = rclpy_implementation.RCLError
#: How often the spinning node looks at the shutdown request, s.
SIGNAL_POLL = 0.1


class StartupError(Exception):
    """A node cannot start; the message is one line for the user."""


#: rcl's text for the parameters file it could not read: the path, then its reason.
_PARAMS_FILE_ERROR = re.compile(r"params file: '--params-file (?P<path>[^']*)'\. "
                                r'Error: (?P<reason>.*)')
#: rcl appends where in its C sources an error was raised: of no use to the user.
_SOURCE_LOCATION = re.compile(r',? at /\S+:\d+')


def _mixed_list(document, prefix=''):
    """Name of the first list in a parsed parameters file mixing integers and floats."""
    if isinstance(document, dict):
        for key, value in document.items():
            found = _mixed_list(value, f'{key}')
            if found:
                return found
    elif isinstance(document, list):
        kinds = {type(v) for v in document if isinstance(v, (int, float))
                 and not isinstance(v, bool)}
        if kinds == {int, float}:
            return f'{prefix}: {document} mixes integers and floats (write 0.0, not 0)'
    return None


def _params_file_problem(path, reason):
    """One line naming what is wrong with a parameters file rcl could not parse."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        return f'parameters file {path}: {exc.strerror or exc}'
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1})' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        return f'parameters file {path}: not valid YAML{where}: {problem}'
    if not isinstance(document, dict):
        return (f'parameters file {path}: the top level must map node names to sections '
                f'(e.g. "/**:"), not {type(document).__name__}')
    for name, section in document.items():
        if not isinstance(section, dict) or 'ros__parameters' not in section:
            return f'parameters file {path}: section {name!r} has no ros__parameters'
    mixed = _mixed_list(document)
    if mixed:
        return f'parameters file {path}: {mixed}'
    return f'parameters file {path}: {reason}'


def _init_problem(exc):
    """One line for the RCLError of rclpy.init (its text is rcl's, with C source places)."""
    text = _SOURCE_LOCATION.sub('', str(exc)).strip()
    match = _PARAMS_FILE_ERROR.search(text)
    if match:
        return _params_file_problem(match['path'], match['reason'])
    return f'the ROS arguments: {text}'


def _init(args):
    """
    rclpy.init without rclpy's signal handlers; StartupError with one line if it fails.

    rcl logs its own ERROR line to stderr (fd 2, from C) before the exception: it is held
    back while init runs and given back unless init failed, so the user sees one line.
    """
    sys.stderr.flush()
    saved = os.dup(2)
    failed = None
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RCLError as exc:
            failed = _init_problem(exc)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        if failed is None:
            held.seek(0)
            os.write(2, held.read())
    if failed is not None:
        raise StartupError(failed)


def _spin(node, stop):
    """
    Spin until a shutdown is requested or the context is shut down elsewhere.

    The request is polled: Python runs signal handlers only between rclpy's waits.
    """
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop.requested and executor.context.ok():
            executor.spin_once(timeout_sec=SIGNAL_POLL)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0)    # its __del__ must not outlive the context


def _close(node):
    """Stop the node's own threads, then destroy it; each step once, whatever happens."""
    close = getattr(node, 'close', None)
    try:
        if close is not None:
            close()
    finally:
        node.destroy_node()


def run_node(factory, args=None, name=None):
    """
    Run the usual node main(): init, construct, spin, shut down; return the exit status.

    SIGINT and SIGTERM, however many and whenever, end it cleanly with status 0 (an
    RCLError once shutdown began counts as clean); a StartupError, including a parameters
    file or ROS argument rcl cannot parse, prints one line and returns 2. BLAS runs on
    one thread (:mod:`epp_ros.app.threads`).
    """
    stop = shutdown_on_signals()
    single_blas_thread()
    name = name or getattr(factory, 'node_name', factory.__name__)
    node = None
    try:
        _init(sys.argv if args is None else args)
        if not stop.requested:
            node = factory()
            _spin(node, stop)
    except StartupError as exc:
        print(f'{name}: {exc}', file=sys.stderr)
        return 2
    except ExternalShutdownException:
        pass
    except (RCLError, InvalidHandle):
        if not stop.requested:
            raise
    finally:
        _shut_down(node, stop)
        ignore_signals()
    return 0


def _shut_down(node, stop):
    """Close the node and rclpy; once shutdown was requested, rclpy errors are expected."""
    try:
        if node is not None:
            _close(node)
    except (RCLError, InvalidHandle):
        if not stop.requested:
            raise
    finally:
        rclpy.try_shutdown()
