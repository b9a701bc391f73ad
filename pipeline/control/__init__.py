"""Stage 3: model-based feedforward control simulated at 400 us (paper 004 section 2.3)."""
