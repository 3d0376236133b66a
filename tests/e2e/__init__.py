"""End to end against a real ``depict serve`` (uvicorn) on 127.0.0.1: the servers and files the
modules share are made once for the package (``conftest.py``)."""
