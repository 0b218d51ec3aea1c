"""`dronectl console`: the operator's live console in the browser, flown on a flight session.

`run.py` opens it (session, camera tap, pilot, server); `pilot.py` flies the session one operation at a
time with a command path of its own; `server.py` and `hub.py` serve the page (`static/`) behind the run's
token; `views.py` and `video.py` say what the page is sent. docs/console.md is the user's guide.
"""
