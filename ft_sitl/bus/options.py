"""Broker address and TLS options: ``mqtt://[user[:password]@]host[:port]`` and ``mqtts://``.

``parse_broker_url`` turns a URL (plus optional ``TlsOptions``) into a validated
``BrokerOptions``. ``mqtt://`` is plain TCP, default port 1883; ``mqtts://`` is TLS, default
port 8883, verifying the broker against the system's CA store unless ``TlsOptions.ca_file``
names another CA bundle. User name and password may be percent-encoded (``%40`` for ``@``).
Bad input raises ValueError naming what was wrong (scheme, port, host, a missing file, TLS
options on a plain ``mqtt://`` URL).
"""

from __future__ import annotations

import socket
import ssl
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote, urlsplit

__all__ = ["DEFAULT_PORTS", "SOCKET_OPTIONS", "BrokerOptions", "TlsOptions",
           "parse_broker_url"]

#: Default port per scheme.
DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}

#: Options of every connection to the broker (aiomqtt's ``socket_options``). TCP_NODELAY:
#: paho-mqtt leaves Nagle's algorithm on, so a small message written while the one before
#: is unacknowledged waited for the broker's delayed ACK (40 ms on Linux): a lockstep tick
#: took 40 ms to reach the navigator (docs/wire.md, "Lockstep"; docs/benchmarks.md).
SOCKET_OPTIONS = ((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),)


def _existing_file(name: str, value) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str | Path):
        raise ValueError(f"TLS {name} must be a path, got {type(value).__name__} {value!r}")
    path = Path(value)
    if not path.is_file():
        raise ValueError(f"TLS {name} {str(path)!r} does not exist or is not a file")
    return str(path)


@dataclass(frozen=True)
class TlsOptions:
    """TLS settings for ``mqtts://``.

    ``ca_file``: PEM bundle of the CA(s) that signed the broker's certificate (None: the
    system store). ``cert_file`` / ``key_file``: the client certificate and its key, for
    brokers that require client certificates (both or neither). ``insecure``: do not verify
    the broker's certificate or host name (testing only: it makes TLS trivially
    interceptable). Files are checked to exist on construction.
    """

    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    insecure: bool = False

    def __post_init__(self):
        object.__setattr__(self, "ca_file", _existing_file("ca_file", self.ca_file))
        object.__setattr__(self, "cert_file", _existing_file("cert_file", self.cert_file))
        object.__setattr__(self, "key_file", _existing_file("key_file", self.key_file))
        if (self.cert_file is None) != (self.key_file is None):
            raise ValueError("TLS cert_file and key_file must be given together (the client "
                             f"certificate and its key), got cert_file={self.cert_file!r}, "
                             f"key_file={self.key_file!r}")
        if not isinstance(self.insecure, bool):
            raise ValueError(f"TLS insecure must be True or False, got {self.insecure!r}")

    def ssl_context(self) -> ssl.SSLContext:
        """A client-side ``ssl.SSLContext`` with these settings."""
        ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=self.ca_file)
        if self.cert_file is not None:
            ctx.load_cert_chain(self.cert_file, self.key_file)
        if self.insecure:
            ctx.check_hostname = False
            ctx.verify_mode = ssl.CERT_NONE
        return ctx


@dataclass(frozen=True)
class BrokerOptions:
    """Where and how to connect: host, port, credentials, TLS (None = plain TCP)."""

    host: str
    port: int
    username: str | None = None
    password: str | None = None
    tls: TlsOptions | None = None

    def __post_init__(self):
        if not isinstance(self.host, str) or not self.host:
            raise ValueError(f"broker host must be a non-empty string, got {self.host!r}")
        if isinstance(self.port, bool) or not isinstance(self.port, int) \
                or not 1 <= self.port <= 65535:
            raise ValueError(f"broker port must be an integer in [1, 65535], got {self.port!r}")
        if self.password is not None and self.username is None:
            raise ValueError("a broker password needs a user name")
        if self.tls is not None and not isinstance(self.tls, TlsOptions):
            raise ValueError(f"tls must be a TlsOptions or None, got {type(self.tls).__name__}")

    @property
    def url(self) -> str:
        """The URL, without the password (safe to log)."""
        scheme = "mqtts" if self.tls is not None else "mqtt"
        user = f"{self.username}@" if self.username is not None else ""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{scheme}://{user}{host}:{self.port}"


def parse_broker_url(url: str, tls: TlsOptions | None = None) -> BrokerOptions:
    """Parse ``mqtt://[user[:password]@]host[:port]`` or ``mqtts://...`` into BrokerOptions.

    ``tls`` applies to ``mqtts://`` only (None there means: verify against the system CA
    store); passing it with ``mqtt://`` is an error rather than a silent plain connection.
    """
    if not isinstance(url, str):
        raise ValueError(f"broker URL must be a string, got {type(url).__name__}")
    if "://" not in url:
        raise ValueError(f"broker URL {url!r} has no scheme: use mqtt://host[:port] or "
                         "mqtts://host[:port]")
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in DEFAULT_PORTS:
        raise ValueError(f"broker URL {_redact(url)!r}: scheme must be mqtt:// or mqtts://, "
                         f"got {parts.scheme}://")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise ValueError(f"broker URL {_redact(url)!r}: a path, query or fragment is not "
                         "allowed (only [user[:password]@]host[:port])")
    if tls is not None and not isinstance(tls, TlsOptions):
        raise ValueError(f"tls must be a TlsOptions or None, got {type(tls).__name__}")
    if scheme == "mqtt" and tls is not None:
        raise ValueError(f"broker URL {_redact(url)!r}: TLS options were given but the scheme "
                         "is mqtt:// (plain TCP); use mqtts://")
    try:
        host = parts.hostname
        port = parts.port
    except ValueError as exc:  # urllib: "Port out of range 0-65535" / "Port could not be cast"
        raise ValueError(f"broker URL {_redact(url)!r}: bad port ({exc}); the port must be an "
                         "integer in [1, 65535]") from None
    if not host:
        raise ValueError(f"broker URL {_redact(url)!r}: missing host")
    if port is None:
        if parts.netloc.endswith(":"):
            raise ValueError(f"broker URL {_redact(url)!r}: empty port after ':'")
        port = DEFAULT_PORTS[scheme]
    if not 1 <= port <= 65535:
        raise ValueError(f"broker URL {_redact(url)!r}: port must be in [1, 65535], got {port}")
    username = unquote(parts.username) if parts.username is not None else None
    password = unquote(parts.password) if parts.password is not None else None
    if username == "":
        raise ValueError(f"broker URL {_redact(url)!r}: empty user name before '@'")
    if scheme == "mqtts" and tls is None:
        tls = TlsOptions()
    return BrokerOptions(host=host, port=port, username=username, password=password, tls=tls)


def _redact(url: str) -> str:
    """The URL with any password replaced by ***, for error messages."""
    head, sep, rest = url.partition("://")
    if not sep:
        return url
    netloc, slash, tail = rest.partition("/")
    creds, at, hostport = netloc.rpartition("@")
    if at and ":" in creds:
        creds = creds.split(":", 1)[0] + ":***"
    return f"{head}://{creds}{at}{hostport}{slash}{tail}"
