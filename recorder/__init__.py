"""corraoi's recorder: every file format, one wing each: one run's slot log (``slotlog/``,
MCAP), its Rerun recording (``rerun/``), a sweep's files (``sweeplog/``), live viewers
(``live/``); the MCAP walker, the sink protocol, the names and numbers of the logs and the
views' colours beside them.

This front names nothing: callers import the modules (``corraoi.recorder.slotlog.reader.open_log``,
``corraoi.recorder.slotlog.sink.McapSink``, ``corraoi.recorder.rerun.sink.RerunSink``), so that
reading a log imports neither Rerun nor the writers (docs/architecture.md).
"""
