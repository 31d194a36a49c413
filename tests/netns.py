"""Network testbed for integration tests: hosts in network namespaces of their own, joined by
veth pairs to a bridge in a namespace of its own, with delay, jitter and loss on their links.

Topology of ``Testbed(n, impairment)`` (namespaces mode; every name below exists only inside the
testbed's namespaces, and nothing is added to the root namespace: no address, route or link)::

    host k (netns <base>-h<k>)                    bridge (netns <base>-br)
      lo 127.0.0.1 (up)
      eth0 10.199.0.<k>/24  ----- veth pair -----  p<k>  --  br0 (bridge)

Each host has static neighbour entries for the others (no ARP on the links, so the first
packets are not delayed or lost by address resolution), and IPv6 address generation is off on
the links (no router or neighbour solicitations among the measured traffic).

Impairment: ``Impairment(delay_s, jitter_s, loss, distribution)`` acts on what a host's
``eth0`` SENDS (its egress, toward the bridge): ``tc qdisc add dev eth0 root netem delay D J
[distribution normal] loss L`` in the host's namespace. A packet from host a to host b therefore
crosses exactly one impairment, the sender's: to get "20 ms +- 5 ms and 10 % loss between
agents", give every host ``Impairment(0.020, 0.005, 0.10)``; a round trip then crosses two, for
a mean of 40 ms, a jitter of sqrt(2) times one leg's and a loss of 1 - 0.9**2 = 19 %. (Half on
each end instead would need a second netem on the bridge side of the receiver's veth, and the
halves do not compose exactly: jitters add in quadrature, losses as 1 - (1 - l)**2.)

Where the kernel has no sch_netem, the same impairment is applied in user space
(tests/netns_relay.py): eth0's egress is redirected to a TAP device whose reader delays or drops
each frame and sends it on eth0, past the qdisc. Same place, same semantics; delays end within
about 1 ms of the configured range on an idle or busy 2-core machine (docs/testing.md).

Where namespaces may not be created (not root, or a container without CAP_SYS_ADMIN), the
``loopback`` mode offers the same interface with every host in the root namespace at 127.0.0.1
and no impairment (netem on ``lo`` would delay every process of the machine): ``notes`` says so,
and the pytest fixture (tests/integration/conftest.py) warns and records it.

``probe()`` / ``available()`` say what this machine permits, with the exact reason. Testbed
names are ``fktb-<pid namespace inode>-<pid>-<serial>-<role>``: parallel pytest workers never
collide, and ``sweep_stale()`` (run by every testbed on entry) deletes what a crashed run of
this pid namespace left behind: only names of our prefix whose pid is dead.
"""

from __future__ import annotations

import contextlib
import functools
import gzip
import itertools
import logging
import os
import platform
import re
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

__all__ = [
    "BETWEEN_AGENTS",
    "Capabilities",
    "Distribution",
    "Host",
    "Impairer",
    "Impairment",
    "Mode",
    "Testbed",
    "TestbedError",
    "TestbedWarning",
    "available",
    "probe",
    "sweep_stale",
    "testbed_names",
]

log = logging.getLogger(__name__)

PREFIX = "fktb"
NETNS_DIR = Path("/run/netns")
SUBNET = "10.199.0"  # .<k>/24 for host k: only ever inside a testbed's namespaces
PREFIX_LEN = 24
MAX_HOSTS = 250
LINK = "eth0"  # a host's interface toward the bridge
BRIDGE = "br0"
RELAY_TAP = "imp0"
FIRST_PORT = 20000  # free_port in a namespace: below Linux's ephemeral range (32768-60999)
RELAY = Path(__file__).with_name("netns_relay.py")
RELAY_READY_S = 15.0
COMMAND_TIMEOUT_S = 30.0
STOP_GRACE_S = 3.0
NAME_RE = re.compile(rf"^{PREFIX}-(\d+)-(\d+)-(\d+)-(br|h\d+|probe)$")

_serial = itertools.count()


class TestbedError(RuntimeError):
    """A testbed could not be set up or removed; the message names the command and its error."""

    __test__ = False


class TestbedWarning(UserWarning):
    """The testbed runs with less than asked for (loopback, or a userspace impairment)."""

    __test__ = False


class Mode(StrEnum):
    """Where a testbed's hosts live."""

    NAMESPACES = "namespaces"
    LOOPBACK = "loopback"


class Impairer(StrEnum):
    """What applies a testbed's impairment."""

    NETEM = "netem"  # tc qdisc netem on the host's eth0
    RELAY = "relay"  # tests/netns_relay.py behind a tc mirred redirect of eth0's egress
    NONE = "none"  # no impairment asked for, or loopback (impossible there)


class Distribution(StrEnum):
    """How a delay's jitter is drawn (netem's default is uniform)."""

    UNIFORM = "uniform"  # delay + U(-jitter, +jitter)
    NORMAL = "normal"  # N(delay, jitter**2), netem's ``distribution normal``


@dataclass(frozen=True, slots=True)
class Impairment:
    """What a host's link does to every packet the host sends (netem semantics): delayed by
    ``delay_s`` plus a jitter of ``jitter_s`` (half-width of a uniform, or the standard
    deviation of a normal ``distribution``), then dropped with probability ``loss`` (0..1)."""

    delay_s: float = 0.0
    jitter_s: float = 0.0
    loss: float = 0.0
    distribution: Distribution = Distribution.UNIFORM

    def __post_init__(self) -> None:
        if not self.delay_s >= 0.0:
            raise ValueError(f"impairment delay_s: expected >= 0, got {self.delay_s}")
        if not self.jitter_s >= 0.0:
            raise ValueError(f"impairment jitter_s: expected >= 0, got {self.jitter_s}")
        if not 0.0 <= self.loss < 1.0:
            raise ValueError(f"impairment loss: expected in [0, 1), got {self.loss}")
        object.__setattr__(self, "distribution", Distribution(self.distribution))

    @property
    def round_trip_loss(self) -> float:
        """Loss of a request and its answer between two hosts that both have this impairment."""
        return 1.0 - (1.0 - self.loss) ** 2

    def netem_args(self) -> list[str]:
        """The ``tc qdisc ... netem`` arguments: ``delay 20000us 5000us distribution normal
        loss 10%``."""
        args = ["delay", f"{round(self.delay_s * 1e6)}us"]
        if self.jitter_s > 0.0:
            args.append(f"{round(self.jitter_s * 1e6)}us")
            if self.distribution is Distribution.NORMAL:
                args += ["distribution", "normal"]
        if self.loss > 0.0:
            args += ["loss", f"{self.loss * 100.0:g}%"]
        return args

    def relay_args(self) -> list[str]:
        """The same impairment as arguments of tests/netns_relay.py."""
        return ["--delay-s", repr(self.delay_s), "--jitter-s", repr(self.jitter_s),
                "--distribution", str(self.distribution), "--loss", repr(self.loss)]

    def describe(self) -> str:
        """``20 ms +- 5 ms (normal), 10 % loss``."""
        text = f"{self.delay_s * 1e3:g} ms"
        if self.jitter_s > 0.0:
            text += f" +- {self.jitter_s * 1e3:g} ms ({self.distribution})"
        return text + f", {self.loss * 100.0:g} % loss"


#: "20 ms +- 5 ms and 10 % loss between agents" (issue 30): each host's sent packets, so that
#: each one-way path between two hosts has it once (the module's docstring)
BETWEEN_AGENTS = Impairment(0.020, 0.005, 0.10, Distribution.NORMAL)


@dataclass(frozen=True, slots=True)
class Capabilities:
    """What this machine permits, each with the reason when it does not."""

    namespaces: bool
    namespaces_reason: str
    netem: bool
    netem_reason: str
    relay: bool
    relay_reason: str

    def describe(self) -> str:
        """One line per capability."""
        def line(name: str, ok: bool, reason: str) -> str:
            return f"{name}: {'yes' if ok else 'no'}" + ("" if ok else f" ({reason})")

        return "; ".join([line("network namespaces", self.namespaces, self.namespaces_reason),
                          line("tc netem", self.netem, self.netem_reason),
                          line("userspace impairment", self.relay, self.relay_reason)])


# ---------------------------------------------------------------------------------------------
# commands


def _run(argv: Sequence[str], input_text: str | None = None) -> subprocess.CompletedProcess:
    """Run a setup command; TestbedError naming it and its stderr if it fails."""
    try:
        out = subprocess.run(list(argv), input=input_text, capture_output=True, text=True,
                             timeout=COMMAND_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise TestbedError(f"`{' '.join(argv)}`: {exc}") from exc
    if out.returncode != 0:
        raise TestbedError(f"`{' '.join(argv)}` exited {out.returncode}: "
                           f"{(out.stderr or out.stdout).strip()}")
    return out


def _ip(netns: str, *args: str) -> None:
    _run(["ip", "-n", netns, *args])


def _tc(netns: str, *args: str) -> None:
    _run(["tc", "-n", netns, *args])


def _pid_namespace() -> int:
    return os.stat("/proc/self/ns/pid").st_ino


def testbed_names() -> list[str]:
    """Every network namespace name of our prefix (any process's), sorted."""
    try:
        return sorted(n for n in os.listdir(NETNS_DIR) if NAME_RE.match(n))
    except FileNotFoundError:
        return []


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _pids_in(netns: str) -> list[int]:
    """Pids of the processes whose network namespace is ``netns`` (as ``ip netns pids``)."""
    try:
        target = os.stat(NETNS_DIR / netns)
    except FileNotFoundError:
        return []
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            st = os.stat(f"/proc/{entry}/ns/net")
        except OSError:  # gone meanwhile, or a kernel thread
            continue
        if (st.st_ino, st.st_dev) == (target.st_ino, target.st_dev):
            pids.append(int(entry))
    return pids


def _kill_all_in(netns: str, grace_s: float = STOP_GRACE_S) -> list[int]:
    """SIGTERM every process in ``netns``, SIGKILL what remains after ``grace_s``; returns the
    pids signalled. Our own process never lives in a testbed namespace."""
    pids = [p for p in _pids_in(netns) if p != os.getpid()]
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    while _pids_in(netns) and time.monotonic() < deadline:
        time.sleep(0.02)
    for pid in _pids_in(netns):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + grace_s
    while _pids_in(netns) and time.monotonic() < deadline:
        time.sleep(0.02)
    return pids


def _delete_netns(netns: str) -> None:
    """Kill what runs in ``netns`` and delete it (its veth ends go with it)."""
    _kill_all_in(netns)
    if (NETNS_DIR / netns).exists():
        _run(["ip", "netns", "del", netns])


def sweep_stale() -> list[str]:
    """Delete the namespaces that testbeds of this pid namespace left behind when their process
    died without tearing down (SIGKILL, a crash, pytest-timeout's thread method): names of our
    prefix whose pid is dead. Returns the names deleted."""
    ours = _pid_namespace()
    swept = []
    for name in testbed_names():
        m = NAME_RE.match(name)
        assert m is not None
        if int(m.group(1)) != ours or _pid_alive(int(m.group(2))):
            continue
        try:
            _delete_netns(name)
        except TestbedError as exc:
            log.warning("netns testbed: stale namespace %s not removed: %s", name, exc)
            continue
        swept.append(name)
    if swept:
        log.warning("netns testbed: removed %d stale namespace(s) of dead runs: %s",
                    len(swept), ", ".join(swept))
    return swept


def _base_name() -> str:
    return f"{PREFIX}-{_pid_namespace()}-{os.getpid()}-{next(_serial)}"


# ---------------------------------------------------------------------------------------------
# what this machine permits


def _kernel_config() -> tuple[str | None, str]:
    """(the kernel's build configuration, where it was read) or (None, where it was looked)."""
    release = platform.release()
    places = [Path("/proc/config.gz"), Path(f"/boot/config-{release}")]
    for place in places:
        try:
            if place.suffix == ".gz":
                with gzip.open(place, "rt") as fh:
                    return fh.read(), str(place)
            return place.read_text(), str(place)
        except OSError:
            continue
    return None, " and ".join(str(p) for p in places)


def _netem_kernel_reason() -> str:
    """Why the kernel has no netem, from its configuration and modules where readable."""
    release = platform.release()
    config, where = _kernel_config()
    if config is None:
        return f"kernel {release}: configuration unreadable ({where} absent)"
    if re.search(r"^CONFIG_NET_SCH_NETEM=y", config, re.MULTILINE):
        return f"kernel {release}: {where} has CONFIG_NET_SCH_NETEM=y, yet tc cannot add it"
    modules = re.search(r"^CONFIG_MODULES=y", config, re.MULTILINE) is not None
    if re.search(r"^CONFIG_NET_SCH_NETEM=m", config, re.MULTILINE):
        found = list(Path(f"/lib/modules/{release}").rglob("sch_netem.ko*"))
        if not found:
            return (f"kernel {release}: sch_netem is a module ({where}: CONFIG_NET_SCH_NETEM=m) "
                    f"but no sch_netem.ko* is under /lib/modules/{release} (Ubuntu: install "
                    f"linux-modules-extra-{release})")
        return (f"kernel {release}: module {found[0]} exists but did not load "
                f"(try `modprobe sch_netem` as root)")
    return (f"kernel {release} built without sch_netem ({where}: CONFIG_NET_SCH_NETEM not set"
            + ("" if modules else "; CONFIG_MODULES not set: no module can be loaded") + ")")


@functools.cache
def probe() -> Capabilities:
    """Try what the testbed needs, in a namespace created and deleted for the purpose: creating
    a network namespace, a netem qdisc on a veth, and the userspace impairment's TAP device and
    mirred redirect. Cached for the process."""
    missing = [tool for tool in ("ip", "tc") if shutil.which(tool) is None]
    if missing:
        reason = f"{' and '.join(missing)} not found on PATH (Debian: apt-get install iproute2)"
        return Capabilities(False, reason, False, reason, False, reason)
    sweep_stale()
    name = f"{_base_name()}-probe"
    try:
        _run(["ip", "netns", "add", name])
    except TestbedError as exc:
        reason = f"cannot create a network namespace (euid {os.geteuid()}): {exc}"
        return Capabilities(False, reason, False, reason, False, reason)
    try:
        _ip(name, "link", "add", "probe0", "type", "veth", "peer", "name", "probe1")
        tried = subprocess.run(["tc", "-n", name, "qdisc", "add", "dev", "probe0", "root",
                                "netem", "delay", "1ms"], capture_output=True, text=True,
                               timeout=COMMAND_TIMEOUT_S)
        netem = tried.returncode == 0
        netem_reason = "" if netem else (f"`tc qdisc add dev X root netem delay 1ms` said "
                                         f"{tried.stderr.strip()!r}: {_netem_kernel_reason()}")
        try:
            if not os.access("/dev/net/tun", os.R_OK | os.W_OK):
                raise TestbedError("/dev/net/tun absent or not readable and writable")
            _ip(name, "tuntap", "add", "dev", "probe2", "mode", "tap")
            _tc(name, "qdisc", "add", "dev", "probe1", "clsact")
            _tc(name, "filter", "add", "dev", "probe1", "egress", "u32", "match", "u32", "0",
                "0", "action", "mirred", "egress", "redirect", "dev", "probe2")
            relay, relay_reason = True, ""
        except TestbedError as exc:
            relay, relay_reason = False, str(exc)
    except TestbedError as exc:
        reason = f"cannot create a veth pair in a namespace: {exc}"
        netem, netem_reason, relay, relay_reason = False, reason, False, reason
    finally:
        _delete_netns(name)
    return Capabilities(True, "", netem, netem_reason, relay, relay_reason)


def available() -> tuple[bool, str]:
    """(True, "") where network namespaces and tc netem both work; else (False, the exact
    reason: what failed and why, e.g. the kernel built without sch_netem)."""
    caps = probe()
    if not caps.namespaces:
        return False, caps.namespaces_reason
    if not caps.netem:
        return False, f"tc netem unavailable: {caps.netem_reason}"
    return True, ""


# ---------------------------------------------------------------------------------------------
# the testbed


@dataclass(eq=False)
class Host:
    """Host ``index`` (1-based) of a testbed: its namespace (None in loopback mode), its address
    on the testbed's link (127.0.0.1 in loopback mode) and its impairment as applied."""

    __test__ = False

    testbed: Testbed
    index: int
    netns: str | None
    address: str
    impairment: Impairment | None
    _next_port: Iterator[int] = field(default_factory=lambda: itertools.count(FIRST_PORT))

    def command(self, argv: Sequence[str]) -> list[str]:
        """``argv`` as run inside this host's namespace (``ip netns exec NAME argv``)."""
        argv = [str(a) for a in argv]
        return argv if self.netns is None else ["ip", "netns", "exec", self.netns, *argv]

    def popen(self, argv: Sequence[str], **kwargs: Any) -> subprocess.Popen:
        """Start ``argv`` in this host's namespace (``subprocess.Popen`` keyword arguments;
        ``start_new_session`` defaults to True). Returns at once; the testbed stops the process
        (SIGTERM to its group, SIGKILL after a grace) on exit if it is still running."""
        kwargs.setdefault("start_new_session", True)
        proc = subprocess.Popen(self.command(argv), **kwargs)
        self.testbed._procs.append(proc)
        return proc

    def run(self, argv: Sequence[str], *, timeout_s: float = 60.0, check: bool = True,
            **kwargs: Any) -> subprocess.CompletedProcess:
        """Run ``argv`` in this host's namespace to its end (``subprocess.run`` keyword
        arguments); returns when it has exited; TimeoutExpired after ``timeout_s``, and
        CalledProcessError on a non-zero exit when ``check``."""
        return subprocess.run(self.command(argv), timeout=timeout_s, check=check, **kwargs)

    def free_port(self, kind: str = "udp") -> int:
        """A port free on this host: in a namespace, the next of 20000, 20001, ... (the
        namespace is new and only the test binds there; the same numbers on every host show
        that each has its own port space); in loopback mode, one the kernel just gave
        (bind to 0, read, close), shared by every host."""
        if kind not in ("udp", "tcp"):
            raise ValueError(f"free_port kind: expected 'udp' or 'tcp', got {kind!r}")
        if self.netns is not None:
            return next(self._next_port)
        stype = socket.SOCK_DGRAM if kind == "udp" else socket.SOCK_STREAM
        with socket.socket(socket.AF_INET, stype) as s:
            s.bind(("127.0.0.1", 0))
            return int(s.getsockname()[1])


def _signal(proc: subprocess.Popen, signum: int) -> None:
    """Signal ``proc``'s process group if it leads one (``start_new_session``), else ``proc``."""
    with contextlib.suppress(ProcessLookupError):
        if os.getpgid(proc.pid) == proc.pid:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)


class Testbed:
    """``with Testbed(hosts, impairment) as bed:`` n hosts on one link, each impaired as
    given (one ``Impairment`` for all, or a sequence with one per host, None for none).

    ``mode``: ``"auto"`` (namespaces where permitted, else loopback), ``"namespaces"`` or
    ``"loopback"``. ``impairer``: ``"auto"`` (netem, else the userspace relay), ``"netem"`` or
    ``"relay"``; asking for one the machine lacks raises TestbedError with the reason.
    ``log_dir``: where the relays write their logs (default: the temporary directory).

    Entering sweeps stale namespaces and creates everything, or removes what it created and
    raises. Exiting (a failure, KeyboardInterrupt included) stops every process started in the
    hosts and deletes the namespaces (and so the veth pairs).
    """

    __test__ = False

    def __init__(
        self,
        hosts: int,
        impairment: Impairment | Sequence[Impairment | None] | None = None,
        *,
        mode: Mode | str = "auto",
        impairer: Impairer | str = "auto",
        log_dir: str | Path | None = None,
    ) -> None:
        if not 1 <= hosts <= MAX_HOSTS:
            raise ValueError(f"testbed hosts: expected 1..{MAX_HOSTS}, got {hosts}")
        if impairment is None or isinstance(impairment, Impairment):
            impairments: list[Impairment | None] = [impairment] * hosts
        else:
            impairments = list(impairment)
            if len(impairments) != hosts:
                raise ValueError(f"testbed impairment: expected one per host ({hosts}), got "
                                 f"{len(impairments)}")
        if mode not in ("auto", *Mode):
            raise ValueError(f"testbed mode: expected auto, namespaces or loopback, got {mode!r}")
        if impairer not in ("auto", Impairer.NETEM, Impairer.RELAY):
            raise ValueError(f"testbed impairer: expected auto, netem or relay, got {impairer!r}")
        self._asked_mode = str(mode)
        self._asked_impairer = str(impairer)
        self._impairments = impairments
        self.log_dir = Path(log_dir) if log_dir is not None else Path(tempfile.gettempdir())
        self.base = _base_name()
        self.mode = Mode.LOOPBACK
        self.impairer = Impairer.NONE
        self.notes: list[str] = []  # what the testbed could not do as asked, and why
        self.hosts: list[Host] = []
        self._namespaces: list[str] = []  # created, in creation order
        self._procs: list[subprocess.Popen] = []
        self._relay_logs: dict[int, Path] = {}

    # -- the interface tests use

    def host(self, k: int) -> Host:
        """Host ``k``, 1-based."""
        if not 1 <= k <= len(self.hosts):
            raise IndexError(f"testbed host {k}: expected 1..{len(self.hosts)}")
        return self.hosts[k - 1]

    def address(self, k: int) -> str:
        """Host ``k``'s address on the link (10.199.0.<k>; 127.0.0.1 in loopback mode)."""
        return self.host(k).address

    @property
    def namespaces(self) -> list[str]:
        """The network namespaces this testbed created and has not deleted."""
        return list(self._namespaces)

    @property
    def impaired(self) -> bool:
        """Whether any impairment asked for is in force."""
        return self.impairer is not Impairer.NONE

    def relay_log(self, k: int) -> Path | None:
        """The userspace impairment's log of host ``k`` (its counts, once the testbed has
        exited), or None if it has none."""
        return self._relay_logs.get(k)

    def describe(self) -> str:
        """One line: mode, hosts, impairer and impairments, and the notes."""
        kinds = sorted({i.describe() for i in self._impairments if i is not None})
        asked = " / ".join(kinds) or "none"
        how = f"via {self.impairer}" if self.impaired or not kinds else "NOT applied"
        text = f"{self.mode} testbed, {len(self._impairments)} hosts, impairment {asked} {how}"
        return text + ("" if not self.notes else " (" + "; ".join(self.notes) + ")")

    # -- lifetime

    def __enter__(self) -> Testbed:
        try:
            self._create()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _create(self) -> None:
        wants_impairment = any(i is not None for i in self._impairments)
        if self._asked_mode == Mode.LOOPBACK:
            self._create_loopback(wants_impairment, "loopback mode asked for")
            return
        caps = probe()
        if not caps.namespaces:
            if self._asked_mode == Mode.NAMESPACES:
                raise TestbedError(f"namespaces mode: {caps.namespaces_reason}")
            self._create_loopback(wants_impairment, caps.namespaces_reason)
            return
        self.mode = Mode.NAMESPACES
        if wants_impairment:
            self.impairer = self._choose_impairer(caps)
        sweep_stale()
        bridge = f"{self.base}-br"
        self._add_netns(bridge)
        _ip(bridge, "link", "add", BRIDGE, "type", "bridge")
        _ip(bridge, "link", "set", BRIDGE, "addrgenmode", "none", "up")
        macs = [f"02:99:00:00:{k // 256:02x}:{k % 256:02x}" for k in range(1, len(
            self._impairments) + 1)]
        for k, impairment in enumerate(self._impairments, start=1):
            name = f"{self.base}-h{k}"
            self._add_netns(name)
            port = f"p{k}"
            _ip(bridge, "link", "add", port, "type", "veth", "peer", "name", LINK, "address",
                macs[k - 1], "netns", name)
            _ip(bridge, "link", "set", port, "addrgenmode", "none", "master", BRIDGE, "up")
            _ip(name, "link", "set", "lo", "up")
            _ip(name, "addr", "add", f"{SUBNET}.{k}/{PREFIX_LEN}", "dev", LINK)
            _ip(name, "link", "set", LINK, "addrgenmode", "none", "up")
            neighbours = "".join(
                f"neigh replace {SUBNET}.{j} lladdr {mac} dev {LINK} nud permanent\n"
                for j, mac in enumerate(macs, start=1) if j != k)
            if neighbours:
                _run(["ip", "-n", name, "-batch", "-"], input_text=neighbours)
            host = Host(self, k, name, f"{SUBNET}.{k}", None)
            self.hosts.append(host)
            if impairment is not None:
                self._impair(host, impairment)
                host.impairment = impairment

    def _create_loopback(self, wants_impairment: bool, why: str) -> None:
        self.mode = Mode.LOOPBACK
        self.notes.append(f"loopback testbed: every host in the root namespace at 127.0.0.1 "
                          f"({why})")
        if wants_impairment:
            self.notes.append("no impairment applied: netem on the root namespace's lo would "
                              "delay every process of the machine")
        self.hosts = [Host(self, k, None, "127.0.0.1", None)
                      for k in range(1, len(self._impairments) + 1)]

    def _choose_impairer(self, caps: Capabilities) -> Impairer:
        asked = self._asked_impairer
        if asked in ("auto", Impairer.NETEM) and caps.netem:
            return Impairer.NETEM
        if asked == Impairer.NETEM:
            raise TestbedError(f"impairer netem: {caps.netem_reason}")
        if not caps.relay:
            raise TestbedError(f"impairer relay: {caps.relay_reason}"
                               + ("" if caps.netem else f"; tc netem: {caps.netem_reason}"))
        if asked == "auto":
            self.notes.append(f"tc netem unavailable ({caps.netem_reason}): impairment applied "
                              f"in user space by tests/netns_relay.py instead")
        return Impairer.RELAY

    def _add_netns(self, name: str) -> None:
        _run(["ip", "netns", "add", name])
        self._namespaces.append(name)

    def _impair(self, host: Host, impairment: Impairment) -> None:
        assert host.netns is not None
        if self.impairer is Impairer.NETEM:
            _tc(host.netns, "qdisc", "add", "dev", LINK, "root", "netem",
                *impairment.netem_args())
            return
        log_path = self.log_dir / f"{host.netns}-relay.log"
        self._relay_logs[host.index] = log_path
        with open(log_path, "w") as log_file:
            relay = host.popen([sys.executable, str(RELAY), "--dev", LINK, "--tap", RELAY_TAP,
                                *impairment.relay_args()],
                               stdout=subprocess.PIPE, stderr=log_file, text=True)
        assert relay.stdout is not None
        ready, _, _ = select.select([relay.stdout], [], [], RELAY_READY_S)
        line = relay.stdout.readline() if ready else ""
        relay.stdout.close()
        if line.strip() != "netns-relay: ready":
            raise TestbedError(f"host {host.index}: the userspace impairment printed no ready "
                               f"line within {RELAY_READY_S} s (exit {relay.poll()}; log "
                               f"{log_path}: {log_path.read_text().strip()[-500:]})")
        _ip(host.netns, "link", "set", RELAY_TAP, "addrgenmode", "none", "up")
        _tc(host.netns, "qdisc", "add", "dev", LINK, "clsact")
        _tc(host.netns, "filter", "add", "dev", LINK, "egress", "u32", "match", "u32", "0", "0",
            "action", "mirred", "egress", "redirect", "dev", RELAY_TAP)

    def close(self) -> None:
        """Stop every process started in the hosts and delete the namespaces; idempotent.
        Raises TestbedError naming what could not be removed (after trying everything)."""
        errors = []
        for proc in self._procs:
            if proc.poll() is None:
                _signal(proc, signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE_S
        for proc in self._procs:
            try:
                proc.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                _signal(proc, signal.SIGKILL)
                try:
                    proc.wait(STOP_GRACE_S)
                except subprocess.TimeoutExpired:
                    errors.append(f"pid {proc.pid} ({' '.join(map(str, proc.args))}) "
                                  f"survived SIGKILL")
        self._procs.clear()
        for name in reversed(self._namespaces):
            try:
                _delete_netns(name)
            except TestbedError as exc:
                errors.append(str(exc))
        self._namespaces = [n for n in self._namespaces if (NETNS_DIR / n).exists()]
        if errors:
            raise TestbedError("testbed teardown: " + "; ".join(errors))
