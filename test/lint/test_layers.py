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


"""The package's layers: imports go only down, never in a circle, and core by its packages."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: A module may import its own layer and the layers below it, never one above.
LAYERS = {'core': 0, 'uwb': 1, 'app': 2, 'nodes': 3, 'cli': 3}
#: The packages of core that code outside it imports (each re-exports its modules' names).
CORE_PACKAGES = {'epp_ros.core', 'epp_ros.core.model', 'epp_ros.core.solvers',
                 'epp_ros.core.estimation', 'epp_ros.core.estimation.methods',
                 'epp_ros.core.calibration', 'epp_ros.core.simulation'}


def module_name(path):
    parts = path.relative_to(ROOT).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


MODULES = {module_name(path): path for path in sorted((ROOT / 'epp_ros').rglob('*.py'))}


def imported(name, path):
    """Return the epp_ros modules (or packages) that ``name`` imports, anywhere in it."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = name.split('.')
                package = parts[:len(parts) - node.level + (path.name == '__init__.py')]
                base = '.'.join(package + ([node.module] if node.module else []))
            for alias in node.names:
                submodule = f'{base}.{alias.name}'
                found.add(submodule if submodule in MODULES else base)
    return {module for module in found if module.split('.')[0] == 'epp_ros' and module != name}


GRAPH = {name: imported(name, path) for name, path in MODULES.items()}


def layer(name):
    parts = name.split('.')
    return LAYERS.get(parts[1]) if len(parts) > 1 else None


def test_the_graph_is_read():
    assert 'epp_ros.core.model.boom' in GRAPH['epp_ros.core.model']   # a relative import
    assert 'epp_ros.app.contract' in GRAPH['epp_ros.nodes.driver']
    assert 'epp_ros.core.model.measurements' in GRAPH['epp_ros.core.model.bounds']


@pytest.mark.parametrize('name', sorted(GRAPH))
def test_imports_go_only_down(name):
    upward = {module for module in GRAPH[name]
              if layer(name) is not None and layer(module) is not None
              and layer(module) > layer(name)}
    assert not upward, f'{name} imports a layer above it: {sorted(upward)}'


def test_no_module_imports_itself_through_a_circle():
    state = {}

    def visit(name, trail):
        if state.get(name) == 'done':
            return
        assert state.get(name) != 'open', 'import cycle: ' + ' -> '.join(
            trail[trail.index(name):] + [name])
        state[name] = 'open'
        for module in sorted(GRAPH.get(name, ())):
            visit(module, trail + [name])
        state[name] = 'done'

    for name in sorted(GRAPH):
        visit(name, [])


@pytest.mark.parametrize('name', sorted(name for name in GRAPH if layer(name) != 0))
def test_outside_core_imports_core_by_its_packages(name):
    inner = {module for module in GRAPH[name]
             if module.startswith('epp_ros.core') and module not in CORE_PACKAGES}
    assert not inner, f'{name} imports modules inside core: {sorted(inner)}'


def test_the_installed_package_imports_no_benchmark():
    for name, path in MODULES.items():
        assert 'benchmarks' not in {alias.split('.')[0] for alias in _all_imports(path)}, name


def _all_imports(path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            yield node.module
