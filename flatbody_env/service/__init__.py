"""The analysis service: an HTTP API (FastAPI) and a web page over the analysis, simulations and recordings.

Run it with ``flatbody serve`` (:mod:`flatbody_env.cli.serve`); build the app with
:func:`flatbody_env.service.app.create_app`. Modules: :mod:`~flatbody_env.service.app` (endpoints,
errors), :mod:`~flatbody_env.service.models` (JSON bodies), :mod:`~flatbody_env.service.answers`
(the command's answers), :mod:`~flatbody_env.service.jobs` (worker processes),
:mod:`~flatbody_env.service.store` (SQLite), :mod:`~flatbody_env.service.limits` (bounds),
:mod:`~flatbody_env.service.launch` (``flatbody serve`` in a subprocess on loopback); the page lives in ``page/``.
Its load benchmark (``flatbody bench service``) is :mod:`flatbody_env.bench.service`.
"""
