from egc_app.cli import main

raise SystemExit(main())
