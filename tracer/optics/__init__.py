"""Layer 2, optics: the surface interface and every material, Fresnel and Stokes algebra, the
directed split (the paper's aim), and the eye's pupil law."""
