from dynpush.cli import main

raise SystemExit(main())
