"""The run layer: stage plan, reuse, locking, interrupts, second pass, headline, report, sweeps."""
