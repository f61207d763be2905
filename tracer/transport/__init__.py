"""Layer 5, transport: the render world (Embree scene, eye, materials, lights, environment), the one
path loop every method runs on, and the deterministic specular chains of the analyses."""
