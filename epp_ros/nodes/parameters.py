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

"""Declaring a node's parameters, the shared pump description among them."""
from epp_ros.app.config import ConfigError, pump_config_from_parameters, PUMP_PARAMETERS
from epp_ros.nodes.runtime import StartupError
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter


def declare(node, name, default, description, **descriptor):
    """
    Declare a parameter with a descriptor and return its value.

    Raises
    ------
    StartupError
        When the value given does not fit the parameter (e.g. an integer for a float).

    """
    empty = _empty_list_given(node, name, default)
    try:
        node.declare_parameter(name, [] if empty else default,
                               ParameterDescriptor(description=description, **descriptor),
                               ignore_override=empty)
    except ParameterException as exc:
        raise StartupError(f'{name}: {exc}') from None
    return node.get_parameter(name).value


def _empty_list_given(node, name, default):
    """
    Tell whether a list parameter was given as an empty list.

    rcl reads ``[]`` in a parameters file, which ``ros2 param dump`` writes for an empty
    list, as "no value"; for a list parameter that can only mean the empty list. rclpy
    keeps the overrides in a private attribute only.
    """
    given = node._parameter_overrides.get(name)     # noqa: SLF001 - no public accessor
    return (isinstance(default, list) and given is not None
            and given.type_ == Parameter.Type.NOT_SET)


def declare_pump_parameters(node):
    """
    Declare the shared pump description and return it validated.

    Raises
    ------
    StartupError
        Naming the offending field.

    """
    values = {name: declare(node, name, default, description + ' Read-only.',
                            dynamic_typing=True, read_only=True)
              for name, (default, description) in PUMP_PARAMETERS.items()}
    try:
        return pump_config_from_parameters(values)
    except ConfigError as exc:
        raise StartupError(f'bad pump configuration: {exc}') from None


def pump_id(node, frame_id):
    """
    Return the hardware id of this pump in ``/diagnostics``: its namespace and frame.

    ``pump7/pump_base`` under the namespace ``/pump7``, ``pump_base`` at the root: two
    pumps' statuses on one ``/diagnostics`` stay apart.
    """
    namespace = node.get_namespace().strip('/')
    return f'{namespace}/{frame_id}' if namespace else frame_id
