"""Many datagrams in one system call: recvmmsg(2) through ctypes (Linux, IPv4).

A shared GCS port of 240 vehicles receives about 24,000 datagrams a second. Read one at a time
(`socket.recvmsg_into` and its ancillary data), each costs ~5 us of system call and Python: a
tenth of a core. `MultiReceiver.receive` reads up to `VLEN` datagrams per call into fixed slots
of one buffer, and returns their lengths, sources and kernel receive times (SO_TIMESTAMPNS) as
arrays, with no Python per datagram, and the socket's count of datagrams the kernel dropped
because its receive buffer was full (SO_RXQ_OVFL, when the caller enabled it).

A datagram longer than a slot (`SLOT_BYTES`, several times the largest any MAVLink stack
sends) is cut by the kernel; it is flagged (`truncated`) so the caller counts it. The structures
are those of the x86-64 and aarch64 Linux ABI (LP64): `available()` says whether they apply.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import socket
import sys

import numpy as np

#: Datagrams per call, and the bytes of each one's slot (1 MiB in all).
VLEN = 128
SLOT_BYTES = 8192
_MSG_DONTWAIT = 0x40
_MSG_TRUNC = 0x20
_SOCKADDR_IN_BYTES = 16
_STAMP_CMSG_BYTES = 32  # CMSG_SPACE(sizeof(struct timespec)) on LP64
_CMSG_BYTES = 64  # the stamp, then SO_RXQ_OVFL's CMSG_SPACE(sizeof(uint32)) = 24, rounded up
_SO_TIMESTAMPNS = 35  # also its SCM_ type
SO_RXQ_OVFL = 40  # the socket's drop count with each datagram (only once it is not 0)

#: struct mmsghdr on LP64: struct msghdr (name, namelen, iov, iovlen, control, controllen,
#: flags) then msg_len, 64 bytes
_MMSGHDR = np.dtype({
    "names": ["name", "namelen", "iov", "iovlen", "control", "controllen", "flags", "len"],
    "formats": ["<u8", "<u4", "<u8", "<u8", "<u8", "<u8", "<i4", "<u4"],
    "offsets": [0, 8, 16, 24, 32, 40, 48, 56],
    "itemsize": 64,
})
_IOVEC = np.dtype({"names": ["base", "len"], "formats": ["<u8", "<u8"], "offsets": [0, 8],
                   "itemsize": 16})


def _libc_recvmmsg():  # noqa: ANN202
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    fn = getattr(ctypes.CDLL(name, use_errno=True), "recvmmsg", None)
    if fn is not None:
        fn.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_void_p]
        fn.restype = ctypes.c_int
    return fn


_RECVMMSG = _libc_recvmmsg() if sys.platform == "linux" else None


def available(sock: socket.socket) -> bool:
    """recvmmsg and the LP64 layouts apply to this (IPv4 UDP) socket."""
    return (_RECVMMSG is not None and ctypes.sizeof(ctypes.c_void_p) == 8
            and sock.family == socket.AF_INET and sys.byteorder == "little")


class MultiReceiver:
    """recvmmsg on one socket into one buffer (module docstring)."""

    def __init__(self, sock: socket.socket) -> None:
        if not available(sock):
            raise OSError("recvmmsg is not available for this socket")
        self._fd = sock.fileno()
        self.buffer = bytearray(VLEN * SLOT_BYTES)
        self._data = np.frombuffer(self.buffer, dtype=np.uint8)
        self._names = np.zeros((VLEN, _SOCKADDR_IN_BYTES), dtype=np.uint8)
        self._control = np.zeros((VLEN, _CMSG_BYTES), dtype=np.uint8)
        self._iov = np.zeros(VLEN, dtype=_IOVEC)
        self._iov["base"] = self._data.ctypes.data + SLOT_BYTES * np.arange(VLEN, dtype=np.uint64)
        self._iov["len"] = SLOT_BYTES
        template = np.zeros(VLEN, dtype=_MMSGHDR)
        template["name"] = self._names.ctypes.data + _SOCKADDR_IN_BYTES * np.arange(
            VLEN, dtype=np.uint64)
        template["namelen"] = _SOCKADDR_IN_BYTES
        template["iov"] = self._iov.ctypes.data + _IOVEC.itemsize * np.arange(VLEN, dtype=np.uint64)
        template["iovlen"] = 1
        template["control"] = self._control.ctypes.data + _CMSG_BYTES * np.arange(
            VLEN, dtype=np.uint64)
        template["controllen"] = _CMSG_BYTES
        self._template = template
        self._hdrs = template.copy()  # namelen, controllen, flags and len are written back
        self.offsets = SLOT_BYTES * np.arange(VLEN, dtype=np.int64)
        self._addresses: dict[int, tuple[str, int]] = {}

    def receive(self) -> int:
        """Read what the socket holds, up to VLEN datagrams: their count (0: nothing). Raises
        OSError for an error the socket reports (e.g. an ICMP error queued on it)."""
        self._hdrs[:] = self._template
        self._control[:, :16] = 0
        self._control[:, _STAMP_CMSG_BYTES:_STAMP_CMSG_BYTES + 16] = 0
        assert _RECVMMSG is not None
        got = _RECVMMSG(self._fd, self._hdrs.ctypes.data, VLEN, _MSG_DONTWAIT, None)
        if got < 0:
            code = ctypes.get_errno()
            if code in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EINTR):
                return 0
            raise OSError(code, os.strerror(code))
        return got

    def lengths(self, n: int) -> np.ndarray:
        return self._hdrs["len"][:n].astype(np.int64)

    def truncated(self, n: int) -> np.ndarray:
        """Datagrams the kernel cut to the slot."""
        return (self._hdrs["flags"][:n] & _MSG_TRUNC) != 0

    def stamps(self, n: int) -> np.ndarray:
        """Each datagram's kernel receive time [s, Unix] (NaN: none came with it)."""
        c = self._control[:n]
        level = c[:, 8:12].copy().view("<i4").ravel()
        kind = c[:, 12:16].copy().view("<i4").ravel()
        spec = c[:, 16:32].copy().view("<i8")
        ok = ((self._hdrs["controllen"][:n] >= _STAMP_CMSG_BYTES) & (level == socket.SOL_SOCKET)
              & (kind == _SO_TIMESTAMPNS))
        return np.where(ok, spec[:, 0] + spec[:, 1] * 1e-9, np.nan)

    def drops(self, n: int) -> int:
        """The socket's count of datagrams dropped (receive buffer full) as the newest of these
        datagrams carried it (SO_RXQ_OVFL after the stamp; -1: none carried one, the count
        being 0 or the option off). Cumulative since the socket opened."""
        c = self._control[:n, _STAMP_CMSG_BYTES:_STAMP_CMSG_BYTES + 20]
        level = c[:, 8:12].copy().view("<i4").ravel()
        kind = c[:, 12:16].copy().view("<i4").ravel()
        count = c[:, 16:20].copy().view("<u4").ravel()
        ok = ((self._hdrs["controllen"][:n] >= _STAMP_CMSG_BYTES + 20)
              & (level == socket.SOL_SOCKET) & (kind == SO_RXQ_OVFL))
        return int(count[ok].max()) if ok.any() else -1

    def sources(self, n: int) -> list[tuple[str, int]]:
        """Each datagram's source address, as the socket module gives it."""
        raw = self._names[:n]
        keys = ((raw[:, 4:8].copy().view(">u4").ravel().astype(np.int64) << 16)
                | raw[:, 2:4].copy().view(">u2").ravel().astype(np.int64)).tolist()
        known = self._addresses
        out = []
        for key in keys:
            addr = known.get(key)
            if addr is None:
                if len(known) > 65536:  # spoofed sources cannot grow it without bound
                    known.clear()
                addr = known[key] = (socket.inet_ntoa((key >> 16).to_bytes(4, "big")),
                                     key & 0xFFFF)
            out.append(addr)
        return out
