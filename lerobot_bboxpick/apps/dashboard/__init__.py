"""The dashboard of the paper's section 4.3: a local web page over one MuJoCo worker thread.

Load a scene, draw the target's box on the wrist image, run one policy or two side by side, watch the
rollout live and download it. Library logic (``session``, ``boxes``, ``policies``, ``views``,
``episode``) is kept apart from the HTTP layer (``server``, ``box_picker``); FastAPI and uvicorn are
the optional ``dashboard`` extra, imported only by the HTTP modules.
"""
