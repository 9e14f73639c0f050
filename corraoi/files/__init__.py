"""Output files: never presented as complete before they are (the `.partial` protocol), never
written by two processes at once (locks that die with their process), never a sweep
folder's own files written over by anything but the sweep."""
