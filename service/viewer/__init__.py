"""The web viewer (``/ui/`` of ``depict serve``): load an EXR, tune a pipeline of operators on a
downscaled preview, compare before and after, take the full-resolution result away.

* :mod:`.routes`: ``/v1/frames`` (frames kept for a session) and the static page;
* :mod:`.store`: the kept frames on disk, with a time to live and a size cap;
* :mod:`.work`: what runs on the service's workers (inspection, layer pictures, previews);
* ``static/``: ``index.html``, ``app.js``, ``app.css`` (no framework, nothing from another host).
"""
