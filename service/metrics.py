"""Prometheus metrics of the service (prometheus-client), one registry per app.

============================================  =========  ======================================
metric                                        type       labels
============================================  =========  ======================================
``depict_http_requests_total``                counter    ``route``, ``method``, ``status``
``depict_http_request_duration_seconds``      histogram  ``route``, ``method``
``depict_http_requests_in_flight``            gauge
``depict_http_request_bytes_total``           counter    ``route`` (bytes received)
``depict_http_response_bytes_total``          counter    ``route`` (bytes sent)
``depict_jobs_queued``                        gauge      jobs waiting for a worker
``depict_jobs_running``                       gauge      jobs on a worker
``depict_jobs_total``                         counter    ``kind``, ``outcome``
``depict_job_duration_seconds``               histogram  ``kind`` (on the worker)
``depict_operator_duration_seconds``          histogram  ``op``
``depict_workers_ready``                      gauge      warmed-up worker processes alive
``depict_workers_replaced_total``             counter    ``cause``: timeout, died, idle-died,
                                                         error
============================================  =========  ======================================

``route`` is the route template (``/v1/enhance``), ``other`` for unknown paths, so a scan of
random URLs cannot blow up the label set.
"""

from __future__ import annotations

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    generate_latest,
)

LATENCY_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120, 300)


class Metrics:
    """The service's collectors, registered in their own :class:`CollectorRegistry`."""

    content_type = CONTENT_TYPE_LATEST

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        r = self.registry
        self.requests = Counter(
            "depict_http_requests",
            "HTTP requests answered",
            ["route", "method", "status"],
            registry=r,
        )
        self.latency = Histogram(
            "depict_http_request_duration_seconds",
            "HTTP request latency, first byte received to last byte sent",
            ["route", "method"],
            buckets=LATENCY_BUCKETS,
            registry=r,
        )
        self.in_flight = Gauge(
            "depict_http_requests_in_flight", "HTTP requests being handled", registry=r
        )
        self.bytes_in = Counter(
            "depict_http_request_bytes", "request body bytes received", ["route"], registry=r
        )
        self.bytes_out = Counter(
            "depict_http_response_bytes", "response body bytes sent", ["route"], registry=r
        )
        self.queued = Gauge("depict_jobs_queued", "jobs waiting for a worker", registry=r)
        self.running = Gauge("depict_jobs_running", "jobs on a worker", registry=r)
        self.jobs = Counter(
            "depict_jobs", "jobs finished, by outcome", ["kind", "outcome"], registry=r
        )
        self.job_time = Histogram(
            "depict_job_duration_seconds",
            "time a job spent on its worker (read, operators, write)",
            ["kind"],
            buckets=LATENCY_BUCKETS,
            registry=r,
        )
        self.operator_time = Histogram(
            "depict_operator_duration_seconds",
            "time spent in each operator",
            ["op"],
            buckets=LATENCY_BUCKETS,
            registry=r,
        )

        self.workers_ready = Gauge(
            "depict_workers_ready", "warmed-up worker processes alive", registry=r
        )
        self.workers_replaced = Counter(
            "depict_workers_replaced",
            "worker processes replaced, by cause (timeout, died, idle-died, error)",
            ["cause"],
            registry=r,
        )

    def render(self) -> bytes:
        """The text exposition format of every metric."""
        return generate_latest(self.registry)
