"""Ray tracing: Embree's scenes and queries, the upload of meshes into Embree, the analytic ground."""
