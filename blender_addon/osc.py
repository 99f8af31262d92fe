"""Open Sound Control 1.0 packets decoded: what the VMC protocol sends over UDP.

A packet is a message (an address starting with "/", a type tag string starting with ",", then
the arguments, each padded to 4 bytes, big-endian) or a bundle ("#bundle", an 8-byte time tag,
then elements each preceded by its 32-bit size). Types read: i (int32), f (float32), s (string),
b (blob), h (int64), d (float64), T, F, N, I (no data). Anything else, or a size beyond the
packet, is an `OscError`: the caller counts it and goes on.

Pure Python (no bpy): a few dozen lines, so the add-on carries no dependency.
"""

import struct


class OscError(ValueError):
    pass


def _string(data, i):
    end = data.find(b"\0", i)
    if end < 0:
        raise OscError("unterminated string at byte %d" % i)
    try:
        s = data[i:end].decode("utf-8")
    except UnicodeDecodeError as e:
        raise OscError("string at byte %d is not UTF-8" % i) from e
    return s, (end + 4) & ~3


def _message(data):
    address, i = _string(data, 0)
    if not address.startswith("/"):
        raise OscError("address %r does not start with /" % address)
    if i >= len(data):
        return address, []  # old senders omit the type tags of an argument-less message
    tags, i = _string(data, i)
    if not tags.startswith(","):
        raise OscError("type tags %r do not start with ," % tags)
    args = []
    for t in tags[1:]:
        if t in "ifhd":
            fmt, size = {"i": (">i", 4), "f": (">f", 4), "h": (">q", 8), "d": (">d", 8)}[t]
            if i + size > len(data):
                raise OscError("argument %r past the end" % t)
            args.append(struct.unpack_from(fmt, data, i)[0])
            i += size
        elif t == "s":
            s, i = _string(data, i)
            args.append(s)
        elif t == "b":
            if i + 4 > len(data):
                raise OscError("blob size past the end")
            (n,) = struct.unpack_from(">i", data, i)
            if n < 0 or i + 4 + n > len(data):
                raise OscError("blob of %d bytes past the end" % n)
            args.append(bytes(data[i + 4:i + 4 + n]))
            i += 4 + ((n + 3) & ~3)
        elif t in "TFNI":
            args.append({"T": True, "F": False, "N": None, "I": float("inf")}[t])
        else:
            raise OscError("unknown type tag %r" % t)
    return address, args


def decode(data, depth=0):
    """The messages of a packet, bundles flattened in order: [(address, [args])]."""
    data = bytes(data)
    if depth > 8:
        raise OscError("bundles nested too deep")
    if data.startswith(b"#bundle\0"):
        if len(data) < 16:
            raise OscError("bundle without a time tag")
        out, i = [], 16
        while i < len(data):
            if i + 4 > len(data):
                raise OscError("bundle element size past the end")
            (n,) = struct.unpack_from(">i", data, i)
            if n < 0 or n % 4 or i + 4 + n > len(data):
                raise OscError("bundle element of %d bytes does not fit" % n)
            out.extend(decode(data[i + 4:i + 4 + n], depth + 1))
            i += 4 + n
        return out
    if len(data) % 4:
        raise OscError("a message's size is not a multiple of 4")
    return [_message(data)]
