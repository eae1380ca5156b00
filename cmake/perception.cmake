# Component: perception (targets are added by the component's owner)
