"""Text from users (object, image and file names, manifest entries) made safe for a terminal or a log.

A name is whatever the .blend file's author typed, or a script set: it may hold escape sequences
(clear the screen, move the cursor), a carriage return that overwrites the line, a newline that
starts a fake line ("bake_ao: baked 99 of 99 objects"), or bidirectional overrides that reorder what
is shown. :func:`escape` writes every character that is not printable as a Python escape (``\\x1b``,
``\\n``, ``\\u202e``); :class:`EscapingStream` does that to everything written through it but the
newlines that end its own lines. No bpy.
"""

__all__ = ["escape", "EscapingStream"]


def _escape_char(ch):
    code = ord(ch)
    if code < 0x100:
        return f"\\x{code:02x}"
    if code < 0x10000:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"


def escape(text, keep="") -> str:
    """``text`` with each non-printable character (controls, separators but the space, formats such as
    bidirectional overrides) written as an escape; characters in ``keep`` (e.g. "\\n") stay as they are."""
    text = str(text)
    if text.isprintable() and not keep:
        return text
    return "".join(ch if ch.isprintable() or ch in keep else _escape_char(ch) for ch in text)


class EscapingStream:
    """A text stream that writes through another one, escaping every non-printable character but
    newline and tab: a message that carries a name cannot move the cursor, clear the screen or
    overwrite a line. Lines the program splits itself stay lines."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text):
        return self.stream.write(escape(text, keep="\n\t"))

    def __getattr__(self, name):  # flush, isatty, fileno, encoding, ...
        return getattr(self.stream, name)
