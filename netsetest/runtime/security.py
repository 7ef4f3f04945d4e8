"""Zenoh's own security for a run: per-run mTLS credentials and the access-control rules of each role.

Everything here configures Zenoh mechanisms; nothing is home-made crypto:

- **mutual TLS** (``tls/`` endpoints, ``transport/link/tls``): a per-run certificate authority signs one
  certificate per role whose common name names the role (``vehicle``, ``collector``, ``node-3``) and one
  for the router.  A session without a certificate of this CA cannot connect at all.
- **access control** (``access_control``, enforced by the router): subjects are the certificates'
  common names; with ``default_permission: deny`` each role may publish only its own keys and receive
  only what it needs (``acl_config``).  Every set of credentials also holds an ``observer`` certificate
  for ``netsetest echo`` / ``watch``: it may receive every key of the run and publish none.  Because every role is a client of one router, the router sees
  every message and its rules are authoritative.  A run spanning hosts has a router on each
  (``netsetest router --connect``): each checks its own clients, and the routers (the ``router``
  certificate, server and client) forward the run's keys to each other.

Credentials are written by :func:`write_credentials` (the ``cryptography`` package): ``ca.pem``,
``NAME.pem`` and ``NAME.key`` (0600) in a directory of mode 0700.  The CA's private key is never
written: to add a role, create a new set.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from netsetest.bus import keys
from netsetest.bus.keys import role_name
from netsetest.config.schema import Scenario
from netsetest.runtime.rolespec import RUN_ID_ENV

SECURITY_MTLS = "mtls+acl"  # the summary's "security" field: Zenoh mTLS + access control at the router
SECURITY_INSECURE = "insecure"  # open peer mesh: any local process can read and forge messages
ROUTER = "router"  # common name of the router's certificate
OBSERVER = "observer"  # common name of the read-only certificate `netsetest echo/watch --credentials` use
RUN_ENV_FILE = "run.env"  # written by `netsetest credentials`: the deployment's run id, for compose's env_file
OBSERVER_ACCESS = "observer.json"  # written by `netsetest run` next to its credentials: run id and router endpoint
ROUTER_HOSTS = ("localhost", "127.0.0.1", ROUTER)  # names the router's certificate is valid for
CA_FILE = "ca.pem"
DIR_MODE, KEY_MODE = 0o700, 0o600
RUN_VALIDITY = datetime.timedelta(days=1)
CLOCK_SKEW = datetime.timedelta(minutes=5)  # not-before in the past: hosts' clocks differ a little


class CredentialsError(ValueError):
    """A credentials directory is missing a file or is readable by others."""


def role_names(sc: Scenario) -> list[str]:
    return [role_name("vehicle"), role_name("collector"), *(role_name("node", i) for i in sc.ids)]


@dataclass(frozen=True)
class Identity:
    """The files one role needs for mTLS."""

    ca: Path
    cert: Path
    key: Path


def identity(directory: str | Path, name: str) -> Identity:
    """The files of role ``name`` in a credentials directory; checks they exist and the key is private."""
    d = Path(directory)
    ident = Identity(d / CA_FILE, d / f"{name}.pem", d / f"{name}.key")
    for f in (ident.ca, ident.cert, ident.key):
        if not f.is_file():
            raise CredentialsError(f"{d}: no {f.name} (create the credentials with `netsetest credentials`)")
    if ident.key.stat().st_mode & 0o077:
        raise CredentialsError(f"{ident.key}: private key readable by group or others (chmod 600)")
    return ident


def _write_private(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, KEY_MODE)
    with os.fdopen(fd, "wb") as f:
        f.write(data)


def write_credentials(
    directory: str | Path, names: Iterable[str], router_hosts: Sequence[str] = ROUTER_HOSTS, validity: datetime.timedelta = RUN_VALIDITY
) -> Path:
    """A fresh CA and one certificate + key per name, the router and the observer in ``directory`` (created 0700)."""
    # imported here: a role process only reads credentials, and cryptography costs it ~8 MB and 20 ms
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    def _name(cn: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    def _san(host: str) -> x509.GeneralName:
        try:
            return x509.IPAddress(ipaddress.ip_address(host))
        except ValueError:
            return x509.DNSName(host)

    d = Path(directory)
    d.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
    d.chmod(DIR_MODE)
    now = datetime.datetime.now(datetime.timezone.utc)
    start, end = now - CLOCK_SKEW, now + validity
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = _name(f"netsetest CA {now:%Y%m%dT%H%M%S}")
    ca = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    (d / CA_FILE).write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    for name in [ROUTER, OBSERVER, *names]:
        key = ec.generate_private_key(ec.SECP256R1())
        hosts = list(router_hosts) if name == ROUTER else [name]
        # the router also opens links, to the run's other routers (`netsetest router --connect`): a client there
        usage = [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH] if name == ROUTER else [ExtendedKeyUsageOID.CLIENT_AUTH]
        cert = (
            x509.CertificateBuilder()
            .subject_name(_name(name))
            .issuer_name(ca_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(start)
            .not_valid_after(end)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.SubjectAlternativeName([_san(h) for h in hosts]), critical=False)
            .add_extension(x509.ExtendedKeyUsage(usage), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256())
        )
        (d / f"{name}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
        _write_private(
            d / f"{name}.key",
            key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()),
        )
    return d


def tls_settings(ident: Identity, listen: bool) -> dict[str, object]:
    """``transport/link/tls`` of a session: the router listens, roles connect; both sides authenticate."""
    side = "listen" if listen else "connect"
    return {
        "root_ca_certificate": str(ident.ca),
        f"{side}_certificate": str(ident.cert),
        f"{side}_private_key": str(ident.key),
        "enable_mtls": True,
    }


@dataclass(frozen=True)
class Grant:
    """What one role may do: publish on ``publish``, subscribe to and receive ``receive``."""

    publish: tuple[str, ...]
    receive: tuple[str, ...]


def grants(sc: Scenario, run_id: str) -> dict[str, Grant]:
    """Per role (certificate common name): the key expressions of keys.py it may publish and receive."""
    control = (keys.ready_of(run_id, "*"), keys.end(run_id))
    out = {
        role_name("vehicle"): Grant(
            (keys.node_input(run_id, "*"), keys.truth(run_id), keys.end(run_id), keys.ready_of(run_id, role_name("vehicle"))),
            (keys.node_state(run_id, "*"), *control),
        ),
        role_name("collector"): Grant(
            (keys.ready_of(run_id, role_name("collector")),),
            (keys.truth(run_id), keys.node_state(run_id, "*"), *control),
        ),
    }
    out[OBSERVER] = Grant((), (keys.run_root(run_id),))  # reads everything of the run, publishes nothing
    # another router of the run (a run spanning hosts, a router on each): forwards what its own clients may
    # publish and asks for what they may receive; each router checks its own clients against their grants
    out[ROUTER] = Grant((keys.run_root(run_id),), (keys.run_root(run_id),))
    for n in sc.nodes:
        me = role_name("node", n.id)
        neighbours = tuple(keys.node_state(run_id, j) for j in sorted(n.in_weights) if j != n.id)
        readings = tuple(keys.reading(run_id, j) for j in sc.reading_sources(n.id))  # the same step's
        mine = (keys.reading(run_id, n.id),) if sc.publishes_reading(n.id) else ()
        out[me] = Grant(
            (keys.node_state(run_id, n.id), *mine, keys.ready_of(run_id, me)),
            (keys.node_input(run_id, n.id), *neighbours, *readings, *control),
        )
    return out


def acl_config(sc: Scenario, run_id: str) -> dict[str, object]:
    """The router's ``access_control`` section: deny by default, allow each role's :func:`grants`."""
    rules: list[dict[str, object]] = [
        # subscriptions are propagated to publishers (which then send); declarations carry no data
        {"id": "interest", "messages": ["declare_subscriber"], "flows": ["egress"], "permission": "allow", "key_exprs": [keys.run_root(run_id)]},
    ]
    subjects, policies = [], []
    for name, g in grants(sc, run_id).items():
        mine = [f"{name}-subscribe", f"{name}-receive", "interest"]
        if g.publish:  # the observer publishes nothing: no rule at all (Zenoh rejects a rule without keys)
            rules.append({"id": f"{name}-publish", "messages": ["put"], "flows": ["ingress"], "permission": "allow", "key_exprs": list(g.publish)})
            mine.append(f"{name}-publish")
        rules.append({"id": f"{name}-subscribe", "messages": ["declare_subscriber"], "flows": ["ingress"], "permission": "allow", "key_exprs": list(g.receive)})
        rules.append({"id": f"{name}-receive", "messages": ["put"], "flows": ["egress"], "permission": "allow", "key_exprs": list(g.receive)})
        subjects.append({"id": name, "cert_common_names": [name]})
        policies.append({"id": name, "rules": mine, "subjects": [name]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def _tls_paths(ident: Identity, listen: bool) -> dict[str, object]:
    return {f"transport/link/tls/{k}": v for k, v in tls_settings(ident, listen).items()}


def client_settings(ident: Identity) -> dict[str, object]:
    """Zenoh settings of a role that connects to the router with its certificate (TLS links only)."""
    return {"transport/link/protocols": ["tls"], **_tls_paths(ident, listen=False)}


def router_settings(ident: Identity, sc: Scenario, run_id: str) -> dict[str, object]:
    """Zenoh settings of the run's router: TLS links only, client certificates required, the run's ACL; its
    certificate on the links it opens too (to the run's other routers, ``netsetest router --connect``)."""
    return {
        "transport/link/protocols": ["tls"],
        **_tls_paths(ident, listen=True),
        **_tls_paths(ident, listen=False),
        "access_control": acl_config(sc, run_id),
    }


@dataclass(frozen=True)
class ObserverAccess:
    """How an observer reaches a secured run: its identity, the run id and the router's endpoints."""

    identity: Identity
    run_id: str | None
    connect: tuple[str, ...]


def write_observer_access(directory: str | Path, run_id: str, connect: Sequence[str]) -> Path:
    """Write :data:`OBSERVER_ACCESS` (run id and router endpoints) into a credentials directory."""
    path = Path(directory) / OBSERVER_ACCESS
    path.write_text(json.dumps({"run_id": run_id, "connect": list(connect)}) + "\n")
    return path


def observer_access(directory: str | Path) -> ObserverAccess:
    """The observer's identity in ``directory``, with the run id and endpoints :func:`write_observer_access`
    left there (a ``netsetest run``), or the run id of ``run.env`` (``netsetest credentials``), if any."""
    ident = identity(directory, OBSERVER)
    d = Path(directory)
    run_id: str | None = None
    connect: tuple[str, ...] = ()
    if (d / OBSERVER_ACCESS).is_file():
        try:
            doc = json.loads((d / OBSERVER_ACCESS).read_text())
            run_id, connect = str(doc["run_id"]), tuple(str(e) for e in doc["connect"])
        except (ValueError, KeyError, TypeError) as exc:
            raise CredentialsError(f"{d / OBSERVER_ACCESS}: not an observer access file ({exc})") from None
    elif (d / RUN_ENV_FILE).is_file():
        for line in (d / RUN_ENV_FILE).read_text().splitlines():
            name, _, value = line.partition("=")
            if name.strip() == RUN_ID_ENV and value.strip():
                run_id = value.strip()
    return ObserverAccess(ident, run_id, connect)
