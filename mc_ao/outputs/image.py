"""The AO image: "<object>_AO" (or the Image name setting's), its files, the summary line of its object."""

from .. import summaries
from .maps import MapOutput


class ImageOutput(MapOutput):
    """The baked AO (or the bake's quantity) in the object's image, plain or tiled, and its files."""

    name = "image"
    what = "own image"
    keeps_record = True

    @classmethod
    def applies(cls, settings):
        return not settings.vertex_colors

    def summarise(self, job, results):
        result = results[self.quantity]
        per, rate = summaries.throughput(result)
        w, h = self.settings.size
        if self.settings.use_udim:
            tiles = sorted(result.tiles)
            listed = ", ".join(map(str, tiles))
            return (f"{job.object_name}: {len(tiles)} UDIM tile{'s' if len(tiles) != 1 else ''} ({listed}) of {w}x{h} "
                    f"into {job.image_name!r} in {result.seconds:.2f} s{summaries.parallel_words(result)}, {per:.0f} "
                    f"samples per texel, {rate:.2f} M rays/s{self.occlusion_words(job, result)}")
        h, w = result.ao.shape
        if getattr(job, "atlas", False):
            from .. import atlas

            return (f"{job.object_name}: {atlas.summary(job, result)}: {w}x{h} into {job.image_name!r} in "
                    f"{result.seconds:.2f} s, {per:.0f} samples per texel, {rate:.2f} M rays/s")
        sources = f" from {', '.join(s.name for s in job.highpoly)}" if getattr(job, "highpoly", None) else ""
        return (f"{job.object_name}: {w}x{h}{sources} into {job.image_name!r}{self.channel_words(job)} in "
                f"{result.seconds:.2f} s{summaries.parallel_words(result)}, {per:.0f} samples per texel, {rate:.2f} M rays/s"
                f"{self.occlusion_words(job, result)}{summaries.miss_summary(result)}")

    def channel_words(self, job):
        """" and the red channel of 'ORM'" where the map also goes into Channel of Into."""
        s = self.settings
        if s.channel == "NONE" or getattr(job, "quantity", "ao") != s.quantities[0]:
            return ""
        return f" and the {CHANNELS[s.channel]} channel of {s.into!r}"

    def occlusion_words(self, job, result):
        text = summaries.occlusion_summary(job, self.settings, result)
        return f"; {text}" if text else ""


#: A Channel setting in a summary's words.
CHANNELS = {"R": "red", "G": "green", "B": "blue", "A": "alpha"}
