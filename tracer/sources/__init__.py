"""Layer 3, sources: emission blocks and the one light table of every method, and the environment
(uniform, HDRI panorama, the sun) with its importance sampling."""
