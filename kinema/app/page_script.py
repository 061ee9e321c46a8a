"""What the app adds to viser's page in the browser: one script, run once per page.

viser (1.1.1) has no Python API for key events or for its own notices, and draws HTML elements with
``innerHTML``, where a ``<script>`` does not run but an image's ``onload`` does. So the session adds, at
the top of the panel, a 1x1 transparent image (`PAGE_HTML`) whose ``onload`` runs `PAGE_SCRIPT`:

- **Live keys.** While live mode runs (a "Stop live" button exists), the arrow keys and WASD are caught
  on the window in the capture phase, before viser's camera listener on the document, and turned into
  clicks on the Live folder's steer buttons (kinema.app.live_panel.BUTTONS); Enter in the "Live prompt"
  box clicks "Switch prompt". Otherwise, and while a text box has focus, the keys are viser's.
- **F frames the character** (as in Blender or Unity): outside a text box, F clicks the Playback folder's
  "Frame character" button (kinema.app.playback.FRAME_BUTTON), in live mode too.
- **Upload notice.** viser's client says "File uploaded successfully." when the bytes have arrived,
  before the app has read the file, so a file the app then refuses got a green "uploaded successfully"
  and a red "Upload failed" at once. That text (found by its text, in a notification) is replaced as it
  appears by `RECEIVED` (a MutationObserver runs before the browser paints), and the app answers every
  upload with its own notification ("Upload failed", "Session loaded", "Clip loaded", "Rig loaded").
  Replaced rather than hidden: a large file's progress notice then ends in a true line.
"""

from __future__ import annotations

from kinema.app.playback import FRAME_BUTTON

#: the Live folder's steer buttons per key (``event.code``), the labels kinema.app.live_panel gives them
KEYS = {"ArrowUp": "Faster", "KeyW": "Faster", "ArrowDown": "Slower", "KeyS": "Slower", "ArrowLeft": "Turn left",
        "KeyA": "Turn left", "ArrowRight": "Turn right", "KeyD": "Turn right"}
UPLOAD_NOTICE = "File uploaded successfully."
#: what that notice says instead
RECEIVED = "Received; kinema reads it now and answers below."

_KEYS_JS = "{" + ",".join(f"{k}:'{v}'" for k, v in KEYS.items()) + "}"
PAGE_SCRIPT = (
    "if(!window.kinemaPage){window.kinemaPage=1;"
    f"var M={_KEYS_JS};"
    "var B=function(t){var b=document.querySelectorAll('button');for(var i=0;i<b.length;i++)"
    "{if(b[i].textContent.trim()===t)return b[i];}return null;};"
    "var L=function(){return B('Stop live')!==null;};"
    "var F=function(t){return t&&(t.tagName==='INPUT'||t.tagName==='TEXTAREA'||t.isContentEditable);};"
    "window.addEventListener('keydown',function(e){"
    "if(F(e.target)){if(e.key==='Enter'&&L()){var r=e.target.closest('.mantine-Flex-root');"
    "if(r&&r.textContent.indexOf('Live prompt')>=0){var s=B('Switch prompt');if(s)s.click();}}return;}"
    f"if(e.code==='KeyF'&&!e.repeat&&!e.ctrlKey&&!e.metaKey&&!e.altKey){{var f=B('{FRAME_BUTTON}');"
    "if(f){e.preventDefault();e.stopImmediatePropagation();f.click();}return;}"
    "var n=M[e.code];if(!n||!L())return;e.preventDefault();e.stopImmediatePropagation();"
    "if(!e.repeat){var b=B(n);if(b)b.click();}},true);"
    "window.addEventListener('keyup',function(e){if(M[e.code]&&L()&&!F(e.target))e.stopImmediatePropagation();},true);"
    "new MutationObserver(function(){var a=document.querySelectorAll('[role=alert] *');"
    f"for(var i=0;i<a.length;i++){{if(a[i].childElementCount===0&&a[i].textContent==='{UPLOAD_NOTICE}')"
    f"a[i].textContent='{RECEIVED}';}}}}).observe(document.body,{{childList:true,subtree:true,characterData:true}});}}"
)
#: a 1x1 transparent GIF whose onload runs `PAGE_SCRIPT`
PIXEL = "data:image/gif;base64,R0lGODlhAQABAIAAAAAAAP///yH5BAEAAAAALAAAAAABAAEAAAIBRAA7"
PAGE_HTML = f'<img alt="" width="1" height="1" src="{PIXEL}" onload="{PAGE_SCRIPT.replace("&", "&amp;")}">'
