"""Analysis of depictions: the congruence score of a picture against the shape it shows
(:mod:`analysis.score`, LLA Eq. 2) and the comparison bench of Local Light Alignment §7
(:mod:`analysis.compare`: every method under 21 light directions, run through the operator
registry; :mod:`analysis.methods`, :mod:`analysis.result`, :mod:`analysis.pictures`).

Layering: ``ops`` <- ``gbuffer`` <- ``service`` (registry, pipeline, operators) <- ``analysis``
<- the commands and routes that expose it (``depict compare``, ``depict score``,
``/v1/compare``, ``/v1/score``) and ``bench/``. :mod:`analysis.score` needs only ``ops`` and
``gbuffer``, so the ``congruence`` operator uses it; importing this package imports nothing
else.
"""
