"""Zenoh TLS, mutual TLS and access control through ``[sources.zenoh]`` (issue 32, fault 11):
real Zenoh sessions on a loopback ``tls/`` endpoint, certificates made at test time. A peer
whose certificate the daemon's CA did not sign gets nothing in; a peer with the right one gets
in where the access-control table lets it, and nowhere else."""

from __future__ import annotations

import datetime
import ipaddress
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from tdmon.config.daemon import ZenohConfig, ZenohTlsConfig, load_daemon_config
from tdmon.ingest.zenoh_io import zenoh_config
from tests.conftest import free_port

KEY_EXPR = "rig/**"


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _write_key(key: ec.EllipticCurvePrivateKey, path: Path) -> Path:
    path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                       serialization.PrivateFormat.PKCS8,
                                       serialization.NoEncryption()))
    return path


def _certificate(subject: str, issuer: str, public_key: ec.EllipticCurvePublicKey,
                 signer: ec.EllipticCurvePrivateKey, ca: bool) -> x509.Certificate:
    now = datetime.datetime.now(datetime.UTC)
    builder = (x509.CertificateBuilder().subject_name(_name(subject)).issuer_name(_name(issuer))
               .public_key(public_key).serial_number(x509.random_serial_number())
               .not_valid_before(now - datetime.timedelta(minutes=5))
               .not_valid_after(now + datetime.timedelta(days=1))
               .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
    if not ca:
        builder = builder.add_extension(x509.SubjectAlternativeName(
            [x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
    return builder.sign(signer, hashes.SHA256())


class Authority:
    """A certificate authority in a folder: its certificate and the certificates it signs."""

    def __init__(self, folder: Path, name: str) -> None:
        self.folder, self.name = folder, name
        self.key = ec.generate_private_key(ec.SECP256R1())
        self.ca_file = folder / f"{name}-ca.pem"
        self.ca_file.write_bytes(_certificate(name, name, self.key.public_key(), self.key, True)
                                 .public_bytes(serialization.Encoding.PEM))

    def issue(self, common_name: str) -> tuple[Path, Path]:
        """(certificate file, key file) of ``common_name``, signed by this authority."""
        key = ec.generate_private_key(ec.SECP256R1())
        cert = _certificate(common_name, self.name, key.public_key(), self.key, False)
        cert_file = self.folder / f"{common_name}.pem"
        cert_file.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
        return cert_file, _write_key(key, self.folder / f"{common_name}.key")


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Path, Path]]:
    """(ca, certificate, key) of the daemon, a rig's peer, and a rogue peer whose certificate
    another authority signed."""
    folder = tmp_path_factory.mktemp("pki")
    ours, theirs = Authority(folder, "tdmon-ops"), Authority(folder, "rogue")
    return {"daemon": (ours.ca_file, *ours.issue("daemon")),
            "rig": (ours.ca_file, *ours.issue("rig-T1")),
            "rogue": (theirs.ca_file, *theirs.issue("rig-T9"))}


def _tls(files: tuple[Path, Path, Path], mutual: bool = True) -> ZenohTlsConfig:
    ca, cert, key = files
    return ZenohTlsConfig(ca_file=ca, cert_file=cert, key_file=key, mutual=mutual)


class Listener:
    """The daemon's side: a peer session listening on a ``tls/`` endpoint, collecting what
    arrives under ``rig/**``."""

    def __init__(self, config: ZenohConfig) -> None:
        self.received: list[str] = []
        self.lock = threading.Lock()
        self.session = zenoh.open(zenoh_config(config))
        self.subscriber = self.session.declare_subscriber(KEY_EXPR, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.received.append(str(sample.key_expr))

    def close(self) -> None:
        self.subscriber.undeclare()
        self.session.close()


@pytest.fixture
def endpoint() -> str:
    return f"tls/127.0.0.1:{free_port()}"


@pytest.fixture
def listener_factory() -> Iterator[list[Listener]]:
    made: list[Listener] = []
    yield made
    for listener in made:
        listener.close()


def _publish(endpoint: str, tls: ZenohTlsConfig, keys: list[str], rounds: int = 10) -> None:
    """A rig's peer: connect, put each key every 0.2 s ``rounds`` times (the link may take a
    moment to come up), close."""
    config = ZenohConfig(mode="peer", connect=[endpoint], tls=tls)
    session = zenoh.open(zenoh_config(config))
    try:
        for _attempt in range(rounds):
            for key in keys:
                session.put(key, b"1")
            time.sleep(0.2)
    finally:
        session.close()


def test_mutual_tls_lets_in_only_a_peer_with_our_certificate(
        pki: dict[str, tuple[Path, Path, Path]], endpoint: str,
        listener_factory: list[Listener]) -> None:
    listener = Listener(ZenohConfig(mode="peer", listen=[endpoint], tls=_tls(pki["daemon"])))
    listener_factory.append(listener)
    _publish(endpoint, _tls(pki["rogue"]), ["rig/T9/hookload"], rounds=4)
    # the rogue trusts our CA (it knows who it talks to) but shows a certificate we did not sign
    rogue_trusting_us = _tls((pki["daemon"][0], pki["rogue"][1], pki["rogue"][2]))
    _publish(endpoint, rogue_trusting_us, ["rig/T9/torque"], rounds=4)
    # without a certificate at all
    _publish(endpoint, ZenohTlsConfig(ca_file=pki["daemon"][0]), ["rig/T9/rpm"], rounds=4)
    assert listener.received == []
    _publish(endpoint, _tls(pki["rig"]), ["rig/T1/hookload"])
    assert set(listener.received) == {"rig/T1/hookload"}


def test_access_control_lets_a_peer_in_only_where_allowed(
        pki: dict[str, tuple[Path, Path, Path]], endpoint: str,
        listener_factory: list[Listener]) -> None:
    access = {
        "enabled": True, "default_permission": "deny",
        "rules": [
            # the daemon's subscription reaches the peer (else it sends nothing at all)
            {"id": "subscribe", "messages": ["declare_subscriber"], "flows": ["egress"],
             "permission": "allow", "key_exprs": ["rig/**"]},
            # and the peer's samples come in under its own rig only
            {"id": "rig-T1-in", "messages": ["put"], "flows": ["ingress"],
             "permission": "allow", "key_exprs": ["rig/T1/**"]}],
        "subjects": [{"id": "rig-T1", "cert_common_names": ["rig-T1"]}],
        "policies": [{"rules": ["subscribe", "rig-T1-in"], "subjects": ["rig-T1"]}],
    }
    listener = Listener(ZenohConfig(mode="peer", listen=[endpoint], tls=_tls(pki["daemon"]),
                                    access_control=access))
    listener_factory.append(listener)
    _publish(endpoint, _tls(pki["rig"]), ["rig/T1/hookload", "rig/T2/hookload"])
    assert set(listener.received) == {"rig/T1/hookload"}
    assert len(listener.received) >= 1


def test_daemon_file_tls_paths_relative_to_the_file_and_checked(tmp_path: Path) -> None:
    (tmp_path / "certs").mkdir()
    for name in ("ca.pem", "rig.pem", "rig.key"):
        (tmp_path / "certs" / name).write_text("x")
    daemon = tmp_path / "daemon.toml"
    daemon.write_text('prefix = "rig/T1"\n[sources.zenoh]\nlisten = ["tls/127.0.0.1:7447"]\n'
                      '[sources.zenoh.tls]\nca_file = "certs/ca.pem"\ncert_file = "certs/rig.pem"'
                      '\nkey_file = "certs/rig.key"\nmutual = true\n'
                      '[sources.zenoh.access_control]\nenabled = true\n'
                      'default_permission = "deny"\n')
    config = load_daemon_config(daemon)
    zenoh_source = config.sources.zenoh
    assert zenoh_source is not None and zenoh_source.tls is not None
    assert zenoh_source.tls.ca_file == tmp_path / "certs" / "ca.pem"
    assert zenoh_source.access_control == {"enabled": True, "default_permission": "deny"}
    (tmp_path / "certs" / "rig.key").unlink()
    with pytest.raises(Exception, match=r"sources\.zenoh\.tls\.key_file: no such file"):
        load_daemon_config(daemon)


def test_the_fleet_router_reads_the_same_table(pki: dict[str, tuple[Path, Path, Path]],
                                               tmp_path: Path) -> None:
    """``tdmon fleet --zenoh FILE``: the table of ``[sources.zenoh]``, paths relative to it;
    --listen replaces its endpoints and keeps the rest; the session it makes is the mutual
    TLS listener a rig with our certificate reaches."""
    import argparse

    from tdmon.cli.fleet import _session_config

    ca, cert, key = pki["daemon"]
    (tmp_path / "zenoh.toml").write_text(
        f'mode = "router"\nlisten = ["tls/127.0.0.1:1"]\n[tls]\nca_file = "{ca.name}"\n'
        f'cert_file = "{cert.name}"\nkey_file = "{key.name}"\nmutual = true\n'
        '[access_control]\nenabled = false\n')
    (tmp_path / "zenoh.toml").replace(ca.parent / "zenoh.toml")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    args = argparse.Namespace(zenoh=ca.parent / "zenoh.toml", listen=[endpoint], connect=[],
                              mode=None)
    config = _session_config(args)
    assert (config.mode, config.listen) == ("router", [endpoint])
    assert config.tls == _tls(pki["daemon"])
    assert config.access_control == {"enabled": False}
    listener = Listener(config)
    try:
        _publish(endpoint, _tls(pki["rig"]), ["rig/T1/alarm"])
        _publish(endpoint, _tls(pki["rogue"]), ["rig/T9/alarm"], rounds=4)
        assert set(listener.received) == {"rig/T1/alarm"}
    finally:
        listener.close()
