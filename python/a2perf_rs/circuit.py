"""The exact circuit placement cost, computed in Rust (``a2perf-circuit``).

:class:`PlacementCost` has the method names of circuit_training's ``plc_client``
(``get_cost``, ``get_wirelength``, ``get_density_cost``, ``get_congestion_cost``,
``update_node_coords``, ``get_node_location``, ``set_canvas_size``, ``set_placement_grid``,
``set_routes_per_micron``, ``set_macro_routing_allocation``, ``set_congestion_smooth_range``,
``make_soft_macros_square``, ``restore_placement``, …). It starts from the same settings as
``a2perf circuit cost``: those of the ``.plc`` header when ``plc_path`` is given, else the Circuit
Training environment's; the setters override them as the CLI's flags do, and the results equal the
CLI's for the same settings.

Example::

    from a2perf_rs.circuit import PlacementCost

    plc = PlacementCost("netlist.pb.txt", "initial.plc")
    plc.set_congestion_smooth_range(2)
    print(plc.get_cost(), plc.get_density_cost(), plc.get_congestion_cost())
    plc.update_node_coords(0, 100.0, 50.0)
    print(plc.costs()["proxy_cost"])

``soft_macro_rule="name_prefix"`` (default, Google's rule: a macro is soft iff its name starts
with ``Grp``) or ``"type_case"`` (plc_client_os: lower-case ``macro`` is soft).
"""

from ._native import PlacementCost

__all__ = ["PlacementCost"]
