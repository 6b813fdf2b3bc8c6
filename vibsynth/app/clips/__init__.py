"""Haptic clips in the studio: the clip lane tab (:mod:`vibsynth.app.clips.studio`)."""
