import sys as _sys

if _sys.argv[:1] == ["-m"]:  # one of this package's modules runs as a command: see offrl_jax.interrupts
    from offrl_jax.interrupts import quiet_start as _quiet_start

    _quiet_start()
