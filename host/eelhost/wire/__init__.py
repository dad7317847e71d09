"""The wire: the generated protocol module (``protocol``) and the hand-written framing it binds."""
