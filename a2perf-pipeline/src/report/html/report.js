// The report page's behaviour: sort and filter the leaderboard, show or hide curves.
// Names come from result files, which are untrusted: they only ever reach the page as
// textContent, option values and attribute comparisons, never as markup.
(function () {
  'use strict';
  var data = JSON.parse(document.getElementById('report-data').textContent);
  var board = document.getElementById('leaderboard');
  var body = board.tBodies[0];
  var headers = Array.prototype.slice.call(board.tHead.rows[0].cells);

  // Missing values (empty data-sort) go last whichever the direction.
  function compare(a, b, col, numeric, sign) {
    var x = a.cells[col].getAttribute('data-sort') || '';
    var y = b.cells[col].getAttribute('data-sort') || '';
    if (x === '' || y === '') {
      return x === y ? 0 : (x === '' ? 1 : -1);
    }
    if (numeric) {
      return sign * (parseFloat(x) - parseFloat(y));
    }
    return sign * (x < y ? -1 : (x > y ? 1 : 0));
  }

  function sortBy(th) {
    var col = headers.indexOf(th);
    var dir = th.getAttribute('aria-sort') === 'ascending' ? 'descending' : 'ascending';
    headers.forEach(function (h) { h.setAttribute('aria-sort', 'none'); });
    th.setAttribute('aria-sort', dir);
    var numeric = th.getAttribute('data-type') === 'number';
    var sign = dir === 'ascending' ? 1 : -1;
    var rows = Array.prototype.slice.call(body.rows);
    // Ties keep their current order (Array.prototype.sort is stable).
    rows.sort(function (a, b) { return compare(a, b, col, numeric, sign); });
    var fragment = document.createDocumentFragment();
    rows.forEach(function (r) { fragment.appendChild(r); });
    body.appendChild(fragment);
  }

  headers.forEach(function (th) {
    var button = th.querySelector('button');
    if (button) {
      button.addEventListener('click', function () { sortBy(th); });
    }
  });

  var selects = Array.prototype.slice.call(document.querySelectorAll('select[data-facet]'));
  selects.forEach(function (select) {
    (data.facets[select.getAttribute('data-facet')] || []).forEach(function (name) {
      var option = document.createElement('option');
      option.value = name;
      option.textContent = name;
      select.appendChild(option);
    });
    select.addEventListener('change', applyFilters);
  });

  function applyFilters() {
    Array.prototype.forEach.call(body.rows, function (row) {
      row.hidden = !selects.every(function (select) {
        return select.value === '' ||
          row.getAttribute('data-' + select.getAttribute('data-facet')) === select.value;
      });
    });
  }

  Array.prototype.forEach.call(document.querySelectorAll('fieldset[data-plot]'), function (set) {
    var plot = document.getElementById(set.getAttribute('data-plot'));
    if (!plot) {
      return;
    }
    Array.prototype.forEach.call(set.querySelectorAll('input[data-series]'), function (box) {
      box.addEventListener('change', function () {
        var index = box.getAttribute('data-series');
        Array.prototype.forEach.call(plot.querySelectorAll('g.series'), function (g) {
          if (g.getAttribute('data-series') === index) {
            g.style.display = box.checked ? '' : 'none';
          }
        });
      });
    });
  });

  document.documentElement.setAttribute('data-ready', String(performance.now()));
})();
