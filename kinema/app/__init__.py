"""`kinema app`: a web authoring UI on the stock viser package (docs/app.md).

- kinema.app.server: `AppServer` (one viser server, one model, a generation pool, a Session per tab);
- kinema.app.session: a tab's document, motions, scene and generation;
- panels: timeline_panel, playback, constraint_panel, files_panel, rig_panel;
- kinema.app.rigs: the character shown (the model's skeleton or a GLB/BVH rig, its skin, clips, contacts);
- kinema.app.generation: the human and the any-rig model behind one call;
- kinema.app.edits: constraints (JSON form) made from scene actions; kinema.app.document: the session file;
- kinema.app.views / mesh_view / markers / residuals: bones, skinned mesh, constraints, residuals in words.

The human default model is trained on CC BY-NC data (Bandai Namco): motions made with it are for
non-commercial use.
"""
