__version__ = "0.1.0"

#: The version of what a bake writes. Bumped once a release when a bake with unchanged settings writes
#: different values (2: float32 tables and per-ray arithmetic, Fix Seams on by default, thickness's
#: default distance). Every file records it (metadata ``output_version``; a file without it was made
#: by version 1); the batch's fingerprints include it, and a library made by an older version is
#: reported and kept unless the batch is asked to bake it again (``--rebake-older``).
OUTPUT_VERSION = 2
