"""``python -m flatbody_env.cli``: the ``flatbody`` command."""

from flatbody_env.cli.main import main

raise SystemExit(main())
