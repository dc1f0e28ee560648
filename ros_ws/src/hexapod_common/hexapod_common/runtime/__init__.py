"""The ROS runtime every node shares (the only rclpy code below the node shells).

``node_main`` (every node's ``main()``), ``hot_loop`` (the wait-set loop, logging, rclpy
start-up), ``conversions`` (rclpy profiles and messages from the topic table),
``ros_params`` (parameter declaration and binding), ``input_guard`` (checked, signed
inputs and status), ``param_topic`` (the signed parameter records), ``dds_profile`` (the
private Fast DDS profile) and ``lifeline`` (nodes die with their launcher). The nodes of
all three packages import it; it imports only ``hexapod_sim.core``.
"""
