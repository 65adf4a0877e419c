"""Topic names and broker URLs: construction, parsing, and the errors for bad input."""

import ssl

import pytest

from ft_sitl.bus import BrokerOptions, TlsOptions, parse_broker_url, parse_topic, topic
from ft_sitl.bus.topics import KINDS, topic_filter


# --- topics -------------------------------------------------------------------------------------
def test_topic_tree():
    assert topic("0", "telemetry") == "ft-sitl/v1/0/telemetry"
    assert topic("uav_2", "config") == "ft-sitl/v1/uav_2/config"
    for kind in KINDS:
        assert parse_topic(topic("17", kind)) == ("17", kind)


def test_topic_filters():
    assert topic_filter() == "ft-sitl/v1/+/+"
    assert topic_filter("0") == "ft-sitl/v1/0/+"
    assert topic_filter(kind="status") == "ft-sitl/v1/+/status"


@pytest.mark.parametrize("vehicle, message", [
    ("", "1 to 64 characters"),
    ("a/b", "1 to 64 characters"),
    ("+", "1 to 64 characters"),
    ("#", "1 to 64 characters"),
    ("x" * 65, "1 to 64 characters"),
    (0, "must be a string"),
])
def test_bad_vehicle(vehicle, message):
    with pytest.raises(ValueError, match=message):
        topic(vehicle, "telemetry")


def test_bad_kind():
    with pytest.raises(ValueError, match="kind must be one of"):
        topic("0", "video")


@pytest.mark.parametrize("name, message", [
    ("ft-sitl/v1/0", "not of the form"),
    ("ft-sitl/v1/0/telemetry/extra", "not of the form"),
    ("other/v1/0/telemetry", "does not start with ft-sitl/"),
    ("ft-sitl/v2/0/telemetry", "tree version 'v2'"),
    ("ft-sitl/v1/a b/telemetry", "1 to 64 characters"),
    ("ft-sitl/v1/0/video", "kind must be one of"),
])
def test_parse_topic_rejects(name, message):
    with pytest.raises(ValueError, match=message):
        parse_topic(name)


# --- broker URLs --------------------------------------------------------------------------------
def test_plain_url_defaults():
    o = parse_broker_url("mqtt://broker.local")
    assert (o.host, o.port, o.username, o.password, o.tls) == ("broker.local", 1883, None,
                                                                 None, None)
    assert o.url == "mqtt://broker.local:1883"


def test_url_with_credentials_and_port():
    o = parse_broker_url("mqtt://alice:p%40ss%3Aword@10.0.0.5:11883")
    assert (o.host, o.port, o.username, o.password) == ("10.0.0.5", 11883, "alice",
                                                        "p@ss:word")
    assert "p@ss" not in o.url and o.url == "mqtt://alice@10.0.0.5:11883"


def test_ipv6_url():
    o = parse_broker_url("mqtt://[::1]:1884")
    assert (o.host, o.port) == ("::1", 1884)
    assert o.url == "mqtt://[::1]:1884"


def test_mqtts_defaults_to_verified_tls():
    o = parse_broker_url("mqtts://broker.example.org")
    assert o.port == 8883
    assert o.tls == TlsOptions()
    ctx = o.tls.ssl_context()
    assert ctx.verify_mode == ssl.CERT_REQUIRED and ctx.check_hostname


def test_tls_options(tmp_path):
    ca = tmp_path / "ca.pem"
    ca.write_text("x")
    o = parse_broker_url("mqtts://h:9999", TlsOptions(ca_file=str(ca), insecure=True))
    assert o.tls.ca_file == str(ca) and o.tls.insecure
    assert o.url == "mqtts://h:9999"


@pytest.mark.parametrize("url, message", [
    ("http://host", "scheme must be mqtt:// or mqtts://"),
    ("ws://host:80", "scheme must be mqtt:// or mqtts://"),
    ("host:1883", "has no scheme"),
    ("mqtt://", "missing host"),
    ("mqtt://:1883", "missing host"),
    ("mqtt://user:secret@:1883", "missing host"),
    ("mqtt://host:0", r"port must be in \[1, 65535\]"),
    ("mqtt://host:65536", "bad port"),
    ("mqtt://host:-1", "bad port"),
    ("mqtt://host:abc", "bad port"),
    ("mqtt://host:", "empty port"),
    ("mqtt://host/topic", "path, query or fragment"),
    ("mqtt://host?x=1", "path, query or fragment"),
    ("mqtt://@host", "empty user name"),
])
def test_bad_urls(url, message):
    with pytest.raises(ValueError, match=message):
        parse_broker_url(url)


def test_bad_url_message_hides_password():
    with pytest.raises(ValueError) as info:
        parse_broker_url("mqtt://alice:hunter2@host:99999")
    assert "hunter2" not in str(info.value) and "alice:***" in str(info.value)


def test_tls_options_with_plain_scheme(tmp_path):
    with pytest.raises(ValueError, match="use mqtts://"):
        parse_broker_url("mqtt://host", TlsOptions(insecure=True))


@pytest.mark.parametrize("field", ["ca_file", "cert_file", "key_file"])
def test_missing_tls_file(tmp_path, field):
    other = tmp_path / "present.pem"
    other.write_text("x")
    kwargs = {"cert_file": str(other), "key_file": str(other)} if field != "ca_file" else {}
    kwargs[field] = str(tmp_path / "absent.pem")
    with pytest.raises(ValueError, match=f"TLS {field} .*absent.pem.* does not exist"):
        TlsOptions(**kwargs)


def test_cert_without_key(tmp_path):
    cert = tmp_path / "c.pem"
    cert.write_text("x")
    with pytest.raises(ValueError, match="cert_file and key_file must be given together"):
        TlsOptions(cert_file=str(cert))


def test_broker_options_checks():
    with pytest.raises(ValueError, match="port must be an integer"):
        BrokerOptions("h", 0)
    with pytest.raises(ValueError, match="host must be a non-empty string"):
        BrokerOptions("", 1883)
    with pytest.raises(ValueError, match="password needs a user name"):
        BrokerOptions("h", 1883, password="x")
