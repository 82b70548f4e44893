"""`pyclray view`: a scene in the browser, live (scene-format.md, "Interactive view").

server.py serves the page and its WebSocket on 127.0.0.1; session.py is one page's view and its flow
control; controls.py the camera's orbit, pan and dolly; frames.py renders and encodes the images;
watch.py follows the scene file's edits; page/ is the page (HTML, JavaScript, CSS: package data)."""
