# ruff: noqa: I001  (the import order is the order of `depict ops` and the schemas)
"""The built-in operators: one registry entry each, mapping a frame onto ``ops`` functions.

Each module registers its operators with :func:`service.operators.base.register`: it reads the
buffers it needs from the frame, calls the maths in ``ops/`` and writes the enhanced beauty
and/or output layers. Parameters are pydantic models; their ``description`` strings are what
``depict ops``, the HTTP schema and ``openapi/openapi.json`` show.

=========================  ============================================================
module                     operators
=========================  ============================================================
:mod:`.curvature`          ``curvature``
:mod:`.radiance_scaling`   ``radiance_scaling``
:mod:`.light_alignment`    ``light_alignment``
:mod:`.unsharp`            ``unsharp_masking``, ``depth_unsharp_masking``
:mod:`.relief`             ``apparent_relief``
:mod:`.baselines`          ``exaggerated_shading``, ``light_warping``
:mod:`.congruence`         ``congruence``
=========================  ============================================================
"""

from service.operators import curvature  # noqa: F401  (importing registers the operators)
from service.operators import radiance_scaling  # noqa: F401
from service.operators import light_alignment  # noqa: F401
from service.operators import unsharp  # noqa: F401
from service.operators import relief  # noqa: F401
from service.operators import baselines  # noqa: F401
from service.operators import congruence  # noqa: F401
