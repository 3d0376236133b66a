"""Errors raised on bad input: each carries one line a user can act on."""


class FrameError(ValueError):
    """A file, buffer or camera cannot be used as given (bad file, missing buffer, bad camera).

    The message is one line that names what is wrong and, where possible, what to pass instead.
    The CLI turns it into exit code 2, the HTTP service into a 4xx problem+json answer.
    """


class MissingBufferError(FrameError):
    """A buffer an operator needs (normal, depth, a lobe, ...) is not in the frame."""


class MissingCameraError(FrameError):
    """The frame has no camera where one is needed (world-space normals, perspective rays)."""


class LimitError(FrameError):
    """The file is over a configured limit (pixel count, size); refused before decoding pixels."""


class OptionError(FrameError):
    """A read option that does not fit the file (a mapping to channels it lacks, an unknown
    buffer name): the request is wrong, not the file."""


class OutputError(FrameError):
    """An output path that cannot be written safely: it names an input, a special file (FIFO,
    device, socket, directory), or a place that cannot be written."""
