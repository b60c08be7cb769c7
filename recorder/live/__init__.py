"""The live view: a Foxglove WebSocket stream beside recording (``branch``) and a replay of a
recorded or archived session over the same protocol (``replay``). ``publisher`` owns the server
and turns frames into Foxglove messages; nothing here is on the capture path."""
