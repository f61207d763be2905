"""Layer 8, analysis: the figures read off a render and its world: the brightness-theorem comparison,
the aims' coverage, and the HUD figures (symbols, background, contrast, spot)."""
