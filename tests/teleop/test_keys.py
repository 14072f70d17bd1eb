"""Key expressions: layout, instrument id validation, who publishes what."""
from __future__ import annotations

import pytest

from teleop.errors import ConfigError
from teleop.wire import keys
from teleop.wire.messages import Side


def test_stream_keys():
    assert keys.command_key("tsm0") == "teleop/tsm0/master/command"
    assert keys.estimate_key("tsm0") == "teleop/tsm0/slave/estimate"
    assert keys.heartbeat_key("tsm0", Side.MASTER) == "teleop/tsm0/master/heartbeat"
    assert keys.heartbeat_key("tsm0", "slave") == "teleop/tsm0/slave/heartbeat"
    assert keys.key("A-b_9", Side.SLAVE, "estimate") == "teleop/A-b_9/slave/estimate"


def test_liveliness_and_wildcard_keys():
    assert keys.liveliness_key("tsm0", Side.SLAVE) == "teleop/tsm0/slave/alive"
    assert keys.liveliness_key("tsm0", "MASTER") == "teleop/tsm0/master/alive"
    assert keys.liveliness_pattern("tsm0") == "teleop/tsm0/*/alive"
    assert keys.instrument_keys("tsm0") == "teleop/tsm0/**"


@pytest.mark.parametrize("bad", ["", "a/b", "a*", "**", "a b", "tsm0$", "é", None, 3])
def test_invalid_instrument_ids_are_config_errors(bad):
    with pytest.raises(ConfigError, match="instrument.id: .* is not a valid instrument id"):
        keys.validate_instrument_id(bad)
    with pytest.raises(ConfigError):
        keys.command_key(bad)


def test_error_names_where_the_id_came_from():
    with pytest.raises(ConfigError, match=r"^--instrument: 'x/y'"):
        keys.validate_instrument_id("x/y", where="--instrument")


def test_unknown_side_or_stream_and_wrong_publisher():
    with pytest.raises(ConfigError, match="'operator' is not a side"):
        keys.key("tsm0", "operator", "command")
    with pytest.raises(ConfigError, match="'force' is not a stream"):
        keys.key("tsm0", Side.MASTER, "force")
    with pytest.raises(ConfigError, match="the slave does not publish 'command'"):
        keys.key("tsm0", Side.SLAVE, "command")
    with pytest.raises(ConfigError, match="the master does not publish 'estimate'"):
        keys.key("tsm0", Side.MASTER, "estimate")


def test_parse_key_inverts_the_builders():
    assert keys.parse_key(keys.command_key("i1")) == ("i1", Side.MASTER, "command")
    assert keys.parse_key(keys.heartbeat_key("i1", Side.SLAVE)) == ("i1", Side.SLAVE, "heartbeat")
    assert keys.parse_key(keys.liveliness_key("i1", Side.SLAVE)) == ("i1", Side.SLAVE, "alive")
    for bad in ("teleop/i1/master", "other/i1/master/command", "teleop/i1/robot/command",
                "teleop/i1/master/telemetry", "teleop/i*/master/command"):
        with pytest.raises(ConfigError):
            keys.parse_key(bad)
