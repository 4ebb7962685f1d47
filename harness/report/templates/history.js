// Filters of the history page's trend figures (no libraries, no network).
(function () {
  "use strict";
  var scenario = document.getElementById("filter-scenario");
  var adapter = document.getElementById("filter-adapter");
  var changed = document.getElementById("filter-changed");
  var count = document.getElementById("trend-count");
  var figures = document.querySelectorAll("#trend-figures figure");
  if (!scenario) { return; }  // a single run: no figures, no filters
  function apply() {
    var shown = 0;
    Array.prototype.forEach.call(figures, function (figure) {
      var keep = (!scenario.value || figure.getAttribute("data-scenario") === scenario.value) &&
        (!adapter.value || figure.getAttribute("data-adapter") === adapter.value) &&
        (!changed.checked || figure.getAttribute("data-changed") === "yes");
      figure.hidden = !keep;
      shown += keep ? 1 : 0;
    });
    count.textContent = shown + " of " + figures.length + " figures";
  }
  [scenario, adapter, changed].forEach(function (control) { control.addEventListener("change", apply); });
  apply();
})();
