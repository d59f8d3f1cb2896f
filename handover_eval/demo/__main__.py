"""``python -m handover_eval.demo``: the command line of :mod:`handover_eval.cli.demo` (a script,
like ``evaluate.py``; guarded, since the demo's spawned helper process imports this module
again under another name)."""

if __name__ == "__main__":
    from handover_eval.cli.demo import main

    raise SystemExit(main())
