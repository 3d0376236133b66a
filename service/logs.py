"""JSON logs of the service: one object per line, in the server and in its worker processes.

Every line carries the request id of the request it belongs to (:data:`REQUEST_ID`, set by the
request middleware in the server and by the job runner in a worker), so a worker's traceback is
found by the ``request_id`` a client got back in its problem answer.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import logging
import os
import sys
import time
from typing import Any, NoReturn

REQUEST_ID: contextvars.ContextVar[str] = contextvars.ContextVar("request_id", default="-")

#: Loggers given the JSON handler (the root logger catches every library's records).
LOGGERS = ("", "depict", "uvicorn", "uvicorn.error", "py.warnings")


class JsonFormatter(logging.Formatter):
    """One JSON object per line: time, level, logger, message, request id and extra fields."""

    FIELDS = (
        "method",
        "path",
        "route",
        "status",
        "duration_ms",
        "bytes_in",
        "bytes_out",
        "client",
        "pid",
        "reason",
    )

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {
            "ts": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created))
            + f".{int(record.msecs):03d}Z",
            "level": record.levelname.lower(),
            "logger": record.name,
            "msg": record.getMessage(),
            "request_id": getattr(record, "request_id", None) or REQUEST_ID.get(),
        }
        for name in self.FIELDS:
            if hasattr(record, name):
                out[name] = getattr(record, name)
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        return json.dumps(out, default=str)


def configure_logging(level: str = "info") -> None:
    """JSON logs on stderr for every logger (Depict's, uvicorn's, Python warnings, libraries)."""
    handler = logging.StreamHandler()
    handler.setFormatter(JsonFormatter())
    logging.captureWarnings(True)
    for name in LOGGERS:
        logger = logging.getLogger(name)
        logger.handlers = [handler]
        logger.setLevel(level.upper() if name else "WARNING")
        logger.propagate = False
    logging.getLogger("uvicorn.access").disabled = True  # one line per request is ours


def end_process(code: int) -> NoReturn:
    """Flush the logs and the standard streams, then end the process without the interpreter's
    teardown: for a process whose files are all written and closed (the ``depict`` executable, a
    worker), where the teardown only frees memory object by object, unloads Numba's compiler and
    has the OpenImageIO binding print "nanobind: leaked ..." lines. multiprocessing's own exit
    handler runs first where it was used (the one ``atexit`` would run): it stops the daemon
    processes left and unregisters the semaphores still held, which its resource tracker
    otherwise reports as "leaked" on stderr once the process is gone (a batch stopped by
    Ctrl-C while Dask's nannies held their workers' queues)."""
    logging.shutdown()
    mp_util = sys.modules.get("multiprocessing.util")
    if mp_util is not None:
        mp_util._exit_function()  # (what multiprocessing registers with atexit)
    for stream in (sys.stdout, sys.stderr):  # (None where Python started without one)
        if stream is not None:
            with contextlib.suppress(OSError):  # a closed pipe, a full disk: nothing to add
                stream.flush()
    os._exit(code)
