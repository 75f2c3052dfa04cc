// robotconf ui: live updates of a server-rendered page. The pages work without this script;
// with it, the page opens an EventSource on its data-events URL and patches in what changed:
// rows (server-rendered <tr>s, escaped on the server) by robot id and rank, removed ids, and
// the boxes ([data-box]) whose HTML changed. No inline script anywhere: the CSP forbids it.
(function () {
  "use strict";

  var body = document.body;
  var MAX_LOG_LINES = 1000;

  function fragment(html) {
    var template = document.createElement("template");
    template.innerHTML = html;
    return template.content.firstElementChild;
  }

  function rowOf(tbody, id) {
    return tbody.querySelector('tr[data-robot="' + CSS.escape(id) + '"]');
  }

  function placeRow(tbody, row) {
    var rank = row.getAttribute("data-rank");
    var rows = tbody.children;
    for (var i = 0; i < rows.length; i++) {
      if (rows[i].getAttribute("data-rank") > rank) {
        tbody.insertBefore(row, rows[i]);
        return;
      }
    }
    tbody.appendChild(row);
  }

  function applyRows(message) {
    var tbody = document.querySelector("tbody[data-rows]");
    if (!tbody) return;
    if (message.reset) tbody.textContent = "";
    message.removed.forEach(function (id) {
      var old = rowOf(tbody, id);
      if (old) old.remove();
    });
    message.rows.forEach(function (item) {
      var old = rowOf(tbody, item[0]);
      var row = fragment(item[2]);
      if (!row) return;
      var focused = old && old.contains(document.activeElement);
      if (old) old.remove();
      placeRow(tbody, row);
      if (focused) {
        var link = row.querySelector("a");
        if (link) link.focus();
      }
    });
  }

  // A box folded to one line (details[data-fold]) that its reader opened or closed stays so
  // across live updates while the page's own choice (data-fold: open when something is wrong)
  // stays the same; when that changes, the page's choice is shown.
  function keepFold(old, box) {
    var was = old.querySelector("details[data-fold][data-reader]");
    var now = box.querySelector("details[data-fold]");
    if (!was || !now || was.getAttribute("data-fold") !== now.getAttribute("data-fold")) return;
    now.open = was.open;
    now.setAttribute("data-reader", "");
  }

  function applyBoxes(boxes) {
    Object.keys(boxes).forEach(function (name) {
      var old = document.querySelector('[data-box="' + CSS.escape(name) + '"]');
      var box = fragment(boxes[name]);
      if (old && box) {
        keepFold(old, box);
        old.replaceWith(box);
      }
    });
    ages();
  }

  // The reader's own opening or closing of a folded box (a click, or Enter on its summary).
  document.addEventListener("click", function (event) {
    var summary = event.target && event.target.closest && event.target.closest("summary");
    var details = summary && summary.parentElement;
    if (details && details.matches("details[data-fold]")) details.setAttribute("data-reader", "");
  });

  function ages() {
    var now = Date.now() / 1000;
    document.querySelectorAll("time[data-since]").forEach(function (el) {
      if (!el.title) el.title = el.textContent;
      var seconds = Math.max(0, Math.round(now - parseFloat(el.getAttribute("data-since"))));
      var text = seconds < 120 ? seconds + " s ago" : seconds < 7200
        ? Math.round(seconds / 60) + " min ago" : Math.round(seconds / 3600) + " h ago";
      el.textContent = el.hasAttribute("data-short") ? text : text + " (" + el.title + ")";
    });
  }

  function liveNote(text) {
    var note = document.querySelector("[data-live]");
    if (!note) {
      note = document.createElement("span");
      note.setAttribute("data-live", "");
      note.setAttribute("role", "status");
      var nav = document.querySelector("header nav");
      if (nav) nav.appendChild(note);
    }
    note.textContent = text;
  }

  function follow() {
    var url = body.getAttribute("data-events");
    if (!url || !window.EventSource) return;
    url += (url.indexOf("?") < 0 ? "?" : "&") + "v=" + encodeURIComponent(body.getAttribute("data-version") || "");
    var source = new EventSource(url);
    source.addEventListener("open", function () { liveNote("live"); });
    source.addEventListener("error", function () { liveNote("live updates lost: reconnecting…"); });
    source.addEventListener("fleet", function (event) {
      var message = JSON.parse(event.data);
      applyRows(message);
      applyBoxes(message.boxes);
      body.setAttribute("data-version", String(message.v));
      liveNote("live");
    });
  }

  function logTail() {
    var pre = document.querySelector("pre[data-log-tail][data-log-src]");
    if (!pre || !window.EventSource) return;
    var source = new EventSource(pre.getAttribute("data-log-src"));
    // Each (re)connection starts with the log's tail: what was shown goes, not doubled.
    source.addEventListener("open", function () { pre.textContent = ""; });
    source.addEventListener("message", function (event) {
      pre.appendChild(document.createTextNode(event.data + "\n"));
      while (pre.childNodes.length > MAX_LOG_LINES) pre.removeChild(pre.firstChild);
      pre.scrollTop = pre.scrollHeight;
    });
  }

  // A restart the page's operator asked for and the robot has not confirmed yet: its outcome
  // is fetched again each second (for a minute and a half at most) until it is decided.
  function restartOutcome() {
    var shown = document.querySelector('[data-restart-outcome="pending"][data-outcome-src]');
    if (!shown || !window.fetch) return;
    var src = shown.getAttribute("data-outcome-src");
    var tries = 0;
    var timer = setInterval(function () {
      if (++tries > 90) { clearInterval(timer); return; }
      fetch(src, { credentials: "same-origin", cache: "no-store" })
        .then(function (response) { return response.ok ? response.text() : ""; })
        .then(function (html) {
          var fresh = html && fragment(html);
          if (!fresh || !shown.isConnected) return;
          shown.replaceWith(fresh);
          shown = fresh;
          if (fresh.getAttribute("data-restart-outcome") !== "pending") clearInterval(timer);
        })
        .catch(function () { /* the next try */ });
    }, 1000);
  }

  // "/" moves to the robot id search, as on many sites; Escape leaves it.
  document.addEventListener("keydown", function (event) {
    var search = document.querySelector('form[data-filter] input[name="q"]');
    var typing = /^(INPUT|SELECT|TEXTAREA)$/.test((event.target || {}).tagName || "");
    if (event.key === "/" && !typing && search) {
      event.preventDefault();
      search.focus();
    } else if (event.key === "Escape" && event.target === search) {
      search.blur();
    }
  });

  ages();
  setInterval(ages, 1000);
  follow();
  logTail();
  restartOutcome();
})();
