"""After the rays: the denoiser and bent normals."""
