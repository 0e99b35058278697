"""Keep one copy of each <script> in a page's head (the theme and sphinx-thebe can register the same one twice,
and a second copy of an inline script is a JavaScript error in the reader's console)."""


def _keep_first_of_each_script(app, pagename, templatename, context, doctree):
    seen, unique = set(), []
    for script in context.get("script_files", []):
        attributes = tuple(sorted(getattr(script, "attributes", {}).items()))
        key = (getattr(script, "filename", None) or "", attributes)  # inline scripts: None or "", by their body
        if key not in seen:
            seen.add(key)
            unique.append(script)
    context["script_files"][:] = unique


def setup(app):
    app.connect("html-page-context", _keep_first_of_each_script, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
