"""Layer 9, products: one render start to finish and what it writes: output sets, the report, the
preview's tone mapping, the false-colour view and the charts."""
