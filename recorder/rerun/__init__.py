"""One run's Rerun recording: its entities, static styling, default layout and where it goes
(an ``.rrd`` file, a viewer, a forked writer)."""
