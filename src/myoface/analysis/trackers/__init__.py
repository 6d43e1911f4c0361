"""The trackers: each turns frames into one measurement per frame behind one protocol
(:mod:`myoface.analysis.trackers.base`)."""
