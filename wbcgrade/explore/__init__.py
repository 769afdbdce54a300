"""``wbcgrade explore``: steer the grade ``apply`` gives a photo in a live local page, then
save the photo or export the grade.

The pieces (``docs/explore.md`` has the user's view):

- :mod:`.engine`: the one module that calls the colour library (load the
  photo and styles, fit, fast and exact colour maps, LUT export, the
  reproducing command line);
- :mod:`.studio`: the style sources the page switches between (the one it
  opened on, other presets) and the folder saved photos go to;
- :mod:`.jobs`: the slow jobs (exact maps, the loss landscape) in one worker
  process at lower priority, coalesced;
- :mod:`.settings`: what the page controls, checked as it arrives;
- :mod:`.server`: the standard library HTTP server (127.0.0.1, a token in
  every address, the Host header checked) and its routes;
- :mod:`.app`: load, fit, serve, open the browser, stop cleanly;
- ``static/``: the page (plain HTML, CSS and JavaScript; no build step).

Imports here stay light: the job worker's process imports this package
before it lowers its priority.
"""
