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

"""
Every source file carries the copyright and license notice of package.xml (Apache-2.0).

What ament_copyright checks in the package templates; its wheel is not on PyPI, so the
same rule is written here: each Python file starts (after a shebang) with a copyright line
and the Apache License 2.0 notice, and LICENSE holds the license.
"""
from pathlib import Path
import re
import xml.etree.ElementTree as ElementTree

import pytest

ROOT = Path(__file__).resolve().parents[2]
NOTICE = [
    'Licensed under the Apache License, Version 2.0 (the "License");',
    'you may not use this file except in compliance with the License.',
    'You may obtain a copy of the License at',
    'http://www.apache.org/licenses/LICENSE-2.0',
    'Unless required by applicable law or agreed to in writing, software',
    'distributed under the License is distributed on an "AS IS" BASIS,',
    'WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.',
    'See the License for the specific language governing permissions and',
    'limitations under the License.',
]
SOURCES = sorted(path for folder in ('epp_ros', 'benchmarks', 'test', 'launch')
                 for path in (ROOT / folder).rglob('*.py')) + [ROOT / 'setup.py',
                                                               ROOT / 'dev.py']


def header(path):
    """Return the leading comment block of a file, without the comment marks."""
    lines = path.read_text().splitlines()
    if lines and lines[0].startswith('#!'):
        lines = lines[1:]
    block = []
    for line in lines:
        if not line.startswith('#'):
            break
        block.append(line.lstrip('#').strip())
    return [line for line in block if line]


@pytest.mark.copyright
@pytest.mark.linter
@pytest.mark.parametrize('path', SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_source_file_has_the_copyright_and_license_notice(path):
    lines = header(path)
    assert lines and re.fullmatch(r'Copyright (\d{4})(-\d{4})? \S.*', lines[0]), \
        f'{path}: no copyright line at the top'
    assert lines[1:] == NOTICE, f'{path}: the Apache-2.0 notice is missing or altered'


@pytest.mark.copyright
@pytest.mark.linter
def test_license_file_matches_package_xml():
    license_tag = ElementTree.parse(ROOT / 'package.xml').getroot().find('license').text
    assert license_tag == 'Apache-2.0'
    text = (ROOT / 'LICENSE').read_text()
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text
