"""The HTTP service (FastAPI on uvicorn): :func:`service.http.app.create_app` and
:func:`service.http.server.serve` (``depict serve``).

Routes (the contract is ``openapi/openapi.json``, regenerated with ``python -m service.openapi``):

==========================  =====================================================================
``POST /v1/enhance``        multipart ``file`` (EXR) + optional ``pipeline`` (JSON), ``preset``,
                            ``camera`` (JSON), ``map`` (JSON), ``normal_space``, ``debug_layers``,
                            ``output_layer`` -> ``image/x-exr``; ``?preview=png`` -> ``image/png``
``POST /v1/render``         multipart ``mesh`` (OBJ/PLY/STL/GLB/GLTF) + ``scene`` (JSON: width,
                            height, camera, azimuth, elevation, lights) -> canonical EXR
``POST /v1/score``          multipart ``file`` (EXR) + options -> JSON congruence score
``POST /v1/compare``        multipart ``file`` (EXR or mesh) + ``options`` -> JSON comparison
``POST /v1/relief/pick``    multipart ``file`` + ``x``, ``y`` -> the Apparent Relief descriptor
``GET /v1/operators``       every operator with its parameter JSON schema
``/v1/frames``, ``/ui/``    the web viewer: frames kept for a session, previews, the page
                            (:mod:`service.viewer`)
``GET /healthz``            alive (never needs the key, answers while the workers are saturated)
``GET /readyz``             ready: the worker pool is up and an OSMesa context could be created
``GET /metrics``            Prometheus text format (key required unless DEPICT_METRICS_PUBLIC)
==========================  =====================================================================

Where things are:

* :mod:`.app`: ``create_app``, the routers included one line each;
* :mod:`.routes`: one module per group of routes (``frames``, ``analysis``, ``operators``,
  ``health``), each an ``APIRouter`` named ``router``;
* :mod:`.deps`: what routes share, as dependencies (the server's settings, metrics and worker
  pool; a workspace per request);
* :mod:`.forms` and :mod:`.uploads`: form fields into typed requests, uploads saved and checked;
* :mod:`.middleware`: request id, metrics and access log; the API key; request limits;
* :mod:`.errors`: every error as ``application/problem+json`` (:mod:`service.problems`);
* :mod:`.pool`: the worker processes with admission control; pixel work never runs on the event
  loop.
"""
