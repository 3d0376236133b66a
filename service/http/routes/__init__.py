"""The routes of the service, one router per module; :func:`service.http.app.create_app`
includes each. A new route is a new module with an ``APIRouter`` named ``router``, and one
``include_router`` line in ``create_app``."""
