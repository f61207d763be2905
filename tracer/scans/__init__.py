"""Layer 10, scans: many renders or eye positions of one scene: the eyebox scan and parameter sweeps."""
