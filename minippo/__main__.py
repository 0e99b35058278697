from minippo.cli import main

raise SystemExit(main())
